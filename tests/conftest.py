"""Shared test settings.

Hypothesis runs a bounded number of examples with no per-example deadline
(the machine has 2 cores; timing belongs in benchmarks/, never in tests).
"""

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "default", max_examples=25, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("thorough", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("GRAINFORGE_HYPOTHESIS", "default"))


@pytest.fixture
def runner():
    from click.testing import CliRunner

    return CliRunner()

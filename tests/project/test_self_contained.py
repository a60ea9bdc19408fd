"""The repository carries its own reasons: no citation of a file outside it, no tracker numbers.

A reader has the repository and nothing else: design notes live in
docs/design/, and a requirement is stated in words, not as a number of an
issue tracker the reader cannot open.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# assembled from parts so that this file does not match itself
FORBIDDEN = re.compile("|".join([r"[Ii]ssue" + r" [0-9]+", "ALGORITHMS" + r"\.md", r"\.\./" + "shared"]))
TEXT = {".py", ".md", ".toml", ".txt", ".cfg", ".yml", ".yaml", ".cff", ".sh"}


def _files():
    for top in ("src", "docs", "tests", "benchmarks", "examples"):
        for p in sorted((ROOT / top).rglob("*")):
            if p.is_file() and p.suffix in TEXT and "__pycache__" not in p.parts:
                yield p
    for name in ("README.md", "CHANGELOG.md", "pyproject.toml", "Makefile", "mkdocs.yml", "CITATION.cff"):
        if (ROOT / name).is_file():
            yield ROOT / name


def test_no_reference_outside_the_repository():
    hits = []
    for p in _files():
        for n, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if FORBIDDEN.search(line):
                hits.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    assert hits == [], "\n".join(hits)


def test_the_pattern_finds_what_it_must():
    for bad in ("see " + "issue " + "12", "Issue" + " 3 says", "ALGORITHMS" + ".md §2", "../" + "shared/design"):
        assert FORBIDDEN.search(bad), bad
    assert not FORBIDDEN.search("docs/design/algorithms.md §2 and a known issue with it")

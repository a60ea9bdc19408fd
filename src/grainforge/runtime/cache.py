"""Where grainforge keeps what it computes once and reuses: calibration curves, fit designs."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """Where computed curves and designs are cached.

    ``$GRAINFORGE_CACHE`` if set, else ``$XDG_CACHE_HOME/grainforge``, else
    ``~/.cache/grainforge``.

    Returns
    -------
    Path
        The folder (not created here).
    """
    env = os.environ.get("GRAINFORGE_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "grainforge"

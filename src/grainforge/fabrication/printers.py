"""Printer profiles: build volume, resolution and what a printer can reliably make.

Three profiles are built in (:data:`PRINTERS`); users add their own in a TOML
file.  All lengths are in millimetres.

A TOML profile file holds one or more ``[printer.NAME]`` tables::

    [printer.my-sla]
    description = "Desk resin printer"
    technology = "sla"           # polyjet | fdm | sla
    build_volume = [120, 68, 150]
    resolution = 0.05            # smallest reproducible step (mm)
    min_wall = 0.2               # optional, default 4 x resolution
    min_size = 0.5               # optional, default 10 x resolution
    stacking = false             # optional, default true only for polyjet

``--printer file.toml`` selects the file's only profile and
``--printer file.toml#my-sla`` one of several.

Examples
--------
>>> p = get_printer("objet-eden-250")
>>> p.build_volume, p.resolution, p.stacking
((250.0, 250.0, 200.0), 0.032, True)
>>> round(p.default_gap, 3)
0.064
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FileFormatError, InputError

__all__ = ["Printer", "PRINTERS", "get_printer", "load_printers", "TECHNOLOGIES"]

TECHNOLOGIES = ("polyjet", "fdm", "sla")


@dataclass(frozen=True)
class Printer:
    """What grainforge needs to know about a 3D printer.

    Parameters
    ----------
    name : str
    description : str
    technology : {"polyjet", "fdm", "sla"}
    build_volume : (3,) float
        Usable x, y, z extent of one build plate, mm.
    resolution : float
        Smallest reproducible step, mm (PolyJet/SLA: the voxel/pixel size;
        FDM: the nozzle width, which limits features more than the layer).
    layer_height : float
        Layer thickness, mm (defaults to ``resolution``).
    min_wall : float
        Thinnest wall or neck that prints reliably, mm (default 4 x resolution).
    min_size : float
        Smallest grain (equivalent diameter) that prints reliably, mm
        (default 10 x resolution).
    stacking : bool
        Whether parts may be stacked in 3D (support material surrounds every
        part, as on PolyJet machines); otherwise one layer on the bed.
    """

    name: str
    description: str
    technology: str
    build_volume: tuple[float, float, float]
    resolution: float
    layer_height: float | None = None
    min_wall: float | None = None
    min_size: float | None = None
    stacking: bool | None = None
    source: str = field(default="built-in", compare=False)

    def __post_init__(self):
        if self.technology not in TECHNOLOGIES:
            raise InputError(f"printer {self.name!r}: technology must be one of {', '.join(TECHNOLOGIES)}, "
                             f"got {self.technology!r}")
        try:
            bv = tuple(float(x) for x in self.build_volume)
        except (TypeError, ValueError):
            raise InputError(f"printer {self.name!r}: build_volume must be three numbers (mm)") from None
        if len(bv) != 3 or not all(math.isfinite(x) and x > 0 for x in bv):
            raise InputError(f"printer {self.name!r}: build_volume must be three positive numbers (mm), got {bv}")
        object.__setattr__(self, "build_volume", bv)
        res = _positive(self.name, "resolution", self.resolution)
        object.__setattr__(self, "resolution", res)
        defaults = {"layer_height": res, "min_wall": 4 * res, "min_size": 10 * res}
        for key, default in defaults.items():
            value = getattr(self, key)
            object.__setattr__(self, key, default if value is None else _positive(self.name, key, value))
        if self.stacking is None:
            object.__setattr__(self, "stacking", self.technology == "polyjet")
        elif not isinstance(self.stacking, bool):
            raise InputError(f"printer {self.name!r}: stacking must be true or false, got {self.stacking!r}")

    @property
    def default_gap(self) -> float:
        """The default minimum gap between parts: two printer resolutions (mm)."""
        return 2.0 * self.resolution

    @property
    def max_deviation(self) -> float:
        """Largest allowed distance between a mesh and the surface it samples: half the resolution."""
        return 0.5 * self.resolution

    def size_problem(self, equivalent_diameter: float) -> str | None:
        """Why a grain of this equivalent diameter (mm) will not print reliably, or None if it is large enough.

        Parameters
        ----------
        equivalent_diameter : float
            mm.

        Returns
        -------
        str or None

        Examples
        --------
        >>> p = get_printer("generic-fdm")
        >>> p.size_problem(2.0)
        'equivalent diameter 2 mm < reliable size 4 mm'
        >>> p.size_problem(4.0) is None
        True
        """
        if equivalent_diameter >= self.min_size:
            return None
        return f"equivalent diameter {equivalent_diameter:.3g} mm < reliable size {self.min_size:g} mm"

    def size_warning(self, equivalent_diameters) -> str | None:
        """A warning when some grains (equivalent diameters, mm) are below :attr:`min_size`, else None.

        Parameters
        ----------
        equivalent_diameters : array_like of float
            One per grain, mm.

        Returns
        -------
        str or None

        Examples
        --------
        >>> p = get_printer("generic-fdm")
        >>> print(p.size_warning([2.0, 2.1, 5.0]))  # doctest: +NORMALIZE_WHITESPACE
        2 of 3 grains (equivalent diameter 2 to 2.1 mm) are below the reliable size of generic-fdm (4 mm,
        min wall 0.8 mm, resolution 0.4 mm): they will not print reliably; print them at 4 mm or more, or
        on a finer printer.
        >>> p.size_warning([4.0, 5.0]) is None
        True
        """
        d = np.asarray(equivalent_diameters, dtype=np.float64)
        small = d[d < self.min_size]
        if len(small) == 0:
            return None
        lo, hi = float(small.min()), float(small.max())
        span = f"{lo:.3g} mm" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g} to {hi:.3g} mm"
        return (f"{len(small)} of {len(d)} grains (equivalent diameter {span}) are below the reliable size of "
                f"{self.name} ({self.min_size:g} mm, min wall {self.min_wall:g} mm, resolution "
                f"{self.resolution:g} mm): they will not print reliably; print them at {self.min_size:g} mm or "
                f"more, or on a finer printer.")


def _positive(name: str, key: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"printer {name!r}: {key} must be a positive number (mm), got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"printer {name!r}: {key} must be a positive number (mm), got {value!r}")
    return v


#: built-in profiles by name
PRINTERS: dict[str, Printer] = {
    p.name: p
    for p in (
        Printer(
            "objet-eden-250", "Stratasys Objet Eden 250 PolyJet (the paper's printer)", "polyjet",
            (250.0, 250.0, 200.0), 0.032, layer_height=0.016, min_wall=0.1, min_size=0.3,
        ),
        Printer(
            "generic-fdm", "Generic FDM: 0.4 mm nozzle, 0.2 mm layers, one layer of parts on the bed", "fdm",
            (220.0, 220.0, 250.0), 0.4, layer_height=0.2, min_wall=0.8, min_size=4.0,
        ),
        Printer(
            "generic-sla", "Generic resin SLA/MSLA, 50 µm", "sla",
            (120.0, 68.0, 150.0), 0.05, layer_height=0.05, min_wall=0.2, min_size=0.5,
        ),
    )
}

_KEYS = {f.name for f in fields(Printer)} - {"name", "source"}


def load_printers(path: str | Path) -> dict[str, Printer]:
    """Read every ``[printer.NAME]`` table of a TOML file.

    Parameters
    ----------
    path : str or Path
        A TOML file of ``[printer.NAME]`` tables (keys: the fields of :class:`Printer`).

    Returns
    -------
    dict of str to Printer
        In file order.

    Raises
    ------
    ValueError
        If the file is missing, is not valid TOML, has no printer table, an
        unknown key, or a bad value (the message names the printer and key).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such printer profile file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: not a valid TOML file ({exc})") from None
    tables = data.get("printer")
    if not isinstance(tables, dict) or not tables or not all(isinstance(t, dict) for t in tables.values()):
        raise InputError(f"{path}: expected one or more [printer.NAME] tables")
    out = {}
    for name, table in tables.items():
        unknown = sorted(set(table) - _KEYS)
        if unknown:
            raise InputError(f"{path}: printer {name!r}: unknown key {unknown[0]!r} "
                             f"(allowed: {', '.join(sorted(_KEYS))})")
        missing = [k for k in ("technology", "build_volume", "resolution") if k not in table]
        if missing:
            raise InputError(f"{path}: printer {name!r}: missing {missing[0]!r}")
        kw = dict(table)
        kw.setdefault("description", f"user profile from {path.name}")
        out[name] = Printer(name=name, source=str(path), **kw)
    return out


def get_printer(spec: str | Printer) -> Printer:
    """A built-in profile by name, or a user profile as ``file.toml`` / ``file.toml#name``.

    Parameters
    ----------
    spec : str or Printer
        A name of :data:`PRINTERS`, ``file.toml`` (one printer) or ``file.toml#NAME``; a Printer is
        returned as it is.

    Returns
    -------
    Printer

    Raises
    ------
    ValueError
        For an unknown name or a bad profile file.

    Examples
    --------
    >>> get_printer("generic-fdm").resolution
    0.4
    """
    if isinstance(spec, Printer):
        return spec
    spec = str(spec)
    if spec in PRINTERS:
        return PRINTERS[spec]
    file, _, name = spec.partition("#")
    if file.endswith(".toml"):
        profiles = load_printers(file)
        if name:
            if name not in profiles:
                raise InputError(f"{file}: no printer {name!r} (has {', '.join(profiles)})")
            return profiles[name]
        if len(profiles) > 1:
            raise InputError(f"{file} holds several printers ({', '.join(profiles)}); use {file}#NAME")
        return next(iter(profiles.values()))
    raise InputError(f"printer must be one of {', '.join(PRINTERS)} or a TOML profile file, got {spec!r}")

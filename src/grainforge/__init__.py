"""grainforge: realistic, printable 3D grain shapes for geotechnical research.

The three generators of Hanaor et al., *3D printable geomaterials* —
:func:`fso` (Fractal Surface Overlay), :func:`cri` (Contour Rotation
Interpolation) and :func:`dpa` (Directed Polyhedra Aggregation) — and two more,
:func:`angular` and :func:`rf`, each returning an immutable :class:`Grain`.

The names below, and the submodules (``grainforge.geometry.solid``, ...), are imported
on first use, so that ``import grainforge`` is quick (the command line starts,
and answers Ctrl-C, before NumPy and SciPy are loaded).
"""

from ._version import __version__

#: public name -> module that defines it
_EXPORTS = {
    "Contour": ".outline.contours", "build_tray": ".fabrication", "check_mesh": ".fabrication",
    "get_printer": ".fabrication", "Grain": ".grain", "generate": ".methods", "angular": ".methods.angular",
    "cri": ".methods.cri", "dpa": ".methods.dpa", "fso": ".methods.fso", "rf": ".methods.rf",
    "ParameterError": ".params", "load_recipe": ".population", "run_batch": ".population",
}

__all__ = ["__version__", "Grain", "ParameterError", "generate", "fso", "cri", "dpa", "angular", "rf", "Contour", "load_recipe",
           "run_batch",
           "get_printer", "check_mesh", "build_tray"]


def __getattr__(name: str):
    import importlib

    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    elif not name.startswith("__"):
        try:
            value = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

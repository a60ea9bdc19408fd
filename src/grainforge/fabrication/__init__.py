"""From grains to printable files: physical scale, printer profiles, resolution matching,
printability checks and bulk print trays."""

from ..io import read_parts
from ..io.threemf import read_3mf
from .printability import CheckResult, check_mesh
from .printers import PRINTERS, Printer, get_printer, load_printers
from .resolution import Resolution, match_subdivisions
from .scale import SIZE_DEFINITIONS, scale_factor, to_size
from .tray import FileSource, GeneratorSource, TrayPlan, TrayResult, build_tray, plan_tray

__all__ = [
    "SIZE_DEFINITIONS", "scale_factor", "to_size",
    "Printer", "PRINTERS", "get_printer", "load_printers",
    "Resolution", "match_subdivisions",
    "CheckResult", "check_mesh",
    "GeneratorSource", "FileSource", "TrayPlan", "TrayResult", "build_tray", "plan_tray", "read_3mf", "read_parts",
]

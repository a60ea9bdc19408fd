"""grainforge: realistic, printable 3D grain shapes for geotechnical research.

The three generators of Hanaor et al., *3D printable geomaterials*:
:func:`fso` (Fractal Surface Overlay), and the others as they land, each
returning an immutable :class:`Grain`.
"""

from ._version import __version__
from .contours import Contour
from .fabrication import build_tray, check_mesh, get_printer
from .grain import Grain
from .methods import generate
from .methods.angular import angular
from .methods.cri import cri
from .calibration import dpa
from .methods.fso import fso
from .methods.rf import rf
from .params import ParameterError
from .population import load_recipe, run_batch

__all__ = ["__version__", "Grain", "ParameterError", "generate", "fso", "cri", "dpa", "angular", "rf", "Contour", "load_recipe",
           "run_batch",
           "get_printer", "check_mesh", "build_tray"]

"""Hook of ``grainforge generate rf`` (see :mod:`grainforge.cli.generate`): ``--aspect L:I:S``."""

from __future__ import annotations

from .generate_cri import AspectType
from .help_style import option

HELP = (
    "\n\nTarget spectrum from mean section descriptors (--descriptors D2,D3,D8 or --preset, with the CRI "
    "decay rules) or from the grains of real images (--spectrum fd.csv, written by 'grainforge fourier')."
)
EXCLUDE = ("aspect",)


OPTIONS = [
    option("--aspect", "aspect", type=AspectType(3), default=None,
           help="Stretch the grain so that its x:y:z extents are in the ratio L:I:S, e.g. 2:1.5:1."),
]

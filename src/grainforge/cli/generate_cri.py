"""Hook of ``grainforge generate cri`` (see :mod:`grainforge.cli.generate`): ``--aspect L:I:S`` and an
up-front check that every ``--images`` file holds a grain outline."""

from __future__ import annotations

import click

from ..errors import InputError
from .help_style import option
from .options import FloatList

HELP = (
    "\n\nContours from Fourier descriptors (--descriptors D2,D3,D8 or --preset), fractal profiles "
    "(--contour fractal) or three grain images (--images A.png,B.png,C.png)."
)
EXCLUDE = ("aspect",)


class AspectType(FloatList):
    """``L:I:S`` (or ``L,I,S``): three numbers."""

    name = "L:I:S"

    def convert(self, value, param, ctx):
        if isinstance(value, str):
            value = value.replace(":", ",")
        return super().convert(value, param, ctx)


OPTIONS = [
    option("--aspect", "aspect", type=AspectType(3), default=None,
           help="Target ratio L:I:S of the principal dimensions, e.g. 2:1.5:1."),
]


def check(params) -> None:
    """Read every image before any grain is made (a bad one names --images)."""
    from ..methods.cri import load_image_contour

    if params.contour == "image":
        for path in params.images.split(","):
            try:
                load_image_contour(path)
            except InputError as exc:
                raise click.BadParameter(str(exc), param_hint="'--images'") from None

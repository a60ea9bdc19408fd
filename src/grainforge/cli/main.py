"""The ``grainforge`` console script.

:func:`main` is the program: it arms the stop signals first (:func:`grainforge.cli.startup.arm`: a Ctrl-C
while the commands load ends it at once, in one line), then loads the command group
(:data:`grainforge.cli.group.cli`) and runs it.  Importing this module loads only the standard library and
changes no signal handler, so another program (a test) can import it.

The command group and its names (and :class:`~grainforge.cli.interrupts.Terminated`) are here too, for those
who import them from this module (``from grainforge.cli.main import cli``); they are loaded on first use.
"""

from __future__ import annotations

#: the names offered here, loaded when first asked for: name -> the module that defines it
_NAMES = {**dict.fromkeys(("cli", "GrainforgeGroup", "help_sections", "IMAGE_SUFFIXES", "_is_image_request"), "group"),
          "Terminated": "interrupts"}


def main() -> None:  # console-script entry point
    """Run the command line as the process: signals at every moment (:mod:`grainforge.cli.interrupts`)."""
    from .startup import arm

    arm()  # first: a signal while the rest loads ends the process at once, in one line
    from .leaving import run_as_console_script

    def run() -> None:
        from .group import cli

        cli.main(prog_name="grainforge")

    run_as_console_script(run)


def __getattr__(name: str):
    if name in _NAMES:
        import importlib

        value = getattr(importlib.import_module(f"{__package__}.{_NAMES[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""One style for every option's help: ``[default: 2.4; range: [2, 3); required]``, and whole first sentences
as the commands' short help."""

from __future__ import annotations

import click

from ..params import format_number

__all__ = ["HelpOption", "option", "interval_of", "apply_help_style", "unstyled_options"]


class HelpOption(click.Option):
    """An option whose help ends in one style everywhere: ``[default: 2.4; range: [2, 3); required]``.

    Defaults are written as a person would (``10``, ``-5/3``), ranges as
    intervals (``[1, inf)``, ``(0, 100]``), for parameter-derived options and
    for click's own ranges alike.  :func:`apply_help_style` gives every option
    of the CLI this class: every option is declared with :func:`option` (or ``cls=HelpOption``).
    """

    #: set by :func:`param_options` (parameter-derived options have no click default)
    default_text: str | None = None
    interval_text: str | None = None

    def get_help_record(self, ctx):
        if self.hidden:
            return None
        extra = self.get_help_extra(ctx)
        items = []
        default = self.default_text
        if default is None and isinstance(self.show_default, str):
            default = self.show_default
        elif default is None and "default" in extra:
            value = self.default
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                default = format_number(value)
            else:
                default = str(extra["default"])
        if default:
            items.append(f"default: {default}")
        interval = self.interval_text if self.interval_text is not None else interval_of(self.type)
        if interval:
            items.append(f"range: {interval}")
        if self.required:
            items.append("required")
        text = self.help or ""
        if items:
            text = f"{text}  [{'; '.join(items)}]" if text else f"[{'; '.join(items)}]"
        return self.get_help_spec(ctx), text


def interval_of(type_) -> str:
    """``[1, inf)`` for ``click.IntRange(min=1)``; ``""`` for types without a range.

    Examples
    --------
    >>> interval_of(click.IntRange(min=1)), interval_of(click.FloatRange(0, 100, min_open=True)), interval_of(click.INT)
    ('[1, inf)', '(0, 100]', '')
    """
    if not isinstance(type_, (click.IntRange, click.FloatRange)):
        return ""
    lo = "-inf" if type_.min is None else format_number(type_.min)
    hi = "inf" if type_.max is None else format_number(type_.max)
    lb = "(" if (type_.min is None or type_.min_open) else "["
    rb = ")" if (type_.max is None or type_.max_open) else "]"
    return f"{lb}{lo}, {hi}{rb}"


def _first_sentence(text: str) -> str:
    """The first sentence of a help text, not cut inside parentheses (``(Eq. 5)``)."""
    para = " ".join(text.strip().split("\n\n")[0].split())
    depth = 0
    for i, ch in enumerate(para):
        depth += (ch == "(") - (ch == ")")
        if ch == "." and depth == 0 and (i + 1 == len(para) or para[i + 1] == " "):
            return para[: i + 1]
    return para


def option(*param_decls: str, **attrs):
    """``click.option`` with the :class:`HelpOption` style: every option of the command line is declared so.

    Parameters
    ----------
    *param_decls : str
        The option's names (``"--count"``) and, optionally, its parameter's name.
    **attrs
        ``click.option``'s settings (``type``, ``default``, ``help``, ...).

    Returns
    -------
    callable
        The decorator.
    """
    attrs.setdefault("cls", HelpOption)
    return click.option(*param_decls, **attrs)


def unstyled_options(command: click.Command) -> list[str]:
    """The options under ``command`` that are not declared with :func:`option` (click's own ``--help`` and
    ``--version`` aside): ``command path: --option`` each (a test asks for none).

    Parameters
    ----------
    command : click.Command
        The root of the commands to look through.

    Returns
    -------
    list of str
    """
    found = [f"{command.name}: {p.opts[0]}" for p in command.params
             if isinstance(p, click.Option) and not isinstance(p, HelpOption) and p.opts[0] not in ("--help", "--version")]
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            found += [f"{command.name} {line}" for line in unstyled_options(sub)]
    return found


def apply_help_style(command: click.Command) -> None:
    """Give every subcommand under ``command`` a short help that is its first whole sentence (click cuts at the
    first period, e.g. inside ``(Eq. 5)``).

    Parameters
    ----------
    command : click.Command
        The root of the commands.
    """
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            if sub.short_help is None and sub.help:
                sub.short_help = _first_sentence(sub.help)
            apply_help_style(sub)

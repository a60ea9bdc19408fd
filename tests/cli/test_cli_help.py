"""Help text: one style for defaults and ranges, derived from the parameter specs."""

from __future__ import annotations

import re

import click
import pytest

from grainforge.cli.main import cli


def _commands(group=cli, path=()):
    for name, cmd in sorted(group.commands.items()):
        yield path + (name,), cmd
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, path + (name,))
    for name, cmd in sorted(getattr(group, "two_words", {}).items()):  # simulate calibrate material
        yield path + tuple(name.split()), cmd


COMMANDS = list(_commands())


def _help_records(cmd):
    ctx = click.Context(cmd, info_name=cmd.name)
    return [r for p in cmd.get_params(ctx) if (r := p.get_help_record(ctx)) is not None]


@pytest.mark.parametrize("path, cmd", COMMANDS, ids=[" ".join(p) for p, _ in COMMANDS])
def test_defaults_and_ranges_in_one_style(path, cmd):
    for opts, text in _help_records(cmd):
        text = " ".join(text.split())
        assert not re.search(r"x\s*[<>]=?|[<>]=?\s*x\b", text), f"{opts}: click's range syntax in {text!r}"
        # defaults appear only as 'default: X' in the one bracket that ends the text
        assert not re.search(r"[(\[]default[ s]", text), f"{opts}: default outside the bracket style: {text!r}"
        assert text.count("default:") <= 1
        if "default:" in text or "range:" in text:
            tail = r"\[(default: [^\[\]]*?)?(; )?(range: [\[(][^,]*, [^\])]*[\])])?(; required)?\]$"
            assert re.search(tail, text), f"{opts}: not in the [default: X; range: I] style: {text!r}"
        for number in re.findall(r"default: (-?[0-9.]+)", text):
            assert len(number) <= 8, f"{opts}: unreadable default {number}"


def _option_help(path, name):
    cmd = cli
    for p in path:
        cmd = cmd.commands[p]
    return dict((opts.split()[0].rstrip(","), " ".join(text.split())) for opts, text in _help_records(cmd))[name]


def test_parameter_defaults_print_nicely():
    assert _option_help(("generate", "cri"), "--decay").endswith("[default: -5/3,-5/3; range: [-10, 0]]")
    assert _option_help(("generate", "fso"), "--fractal-dimension").endswith("[default: 2.4; range: [2, 3)]")
    assert _option_help(("generate", "fso"), "--amplitude").endswith("[default: 0.1; range: [0, 1]]")
    assert _option_help(("generate", "dpa"), "--exponent").endswith("[default: 1; range: [0.01, 100]]")
    assert _option_help(("generate", "fso"), "--count").endswith("[default: 1; range: [1, inf)]")


def test_k_is_the_papers_K_and_amplitude_says_when_it_is_refused():
    k = _option_help(("generate", "fso"), "--k")
    assert "the paper's amplitude scaling K of Eq. 2" in k and "R0" in k
    assert "star-shaped" in _option_help(("generate", "fso"), "--amplitude")


def test_amplitude_refusal_says_why(runner, tmp_path):
    res = runner.invoke(cli, ["generate", "fso", "--amplitude", "0.9", "--subdivisions", "2", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "--amplitude" in res.output and "star-shaped" in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("path, cmd", [c for c in COMMANDS if isinstance(c[1], click.Group)] + [((), cli)],
                         ids=lambda x: " ".join(x) if isinstance(x, tuple) else "")
def test_command_listings_are_not_cut_mid_sentence(runner, path, cmd):
    res = runner.invoke(cli, [*path, "--help"], terminal_width=100)
    assert res.exit_code == 0
    listing = res.output.split("Commands:")[1]
    entries = dict(e.split(None, 1) for e in re.split(r"\n  (?=\S)", listing.strip()))
    for name, sub in cmd.commands.items():
        shown = " ".join(entries[name].split())
        first = " ".join(sub.help.strip().split("\n\n")[0].split())
        assert first.startswith(shown), f"{name}: listed as {shown!r}"
        assert shown.count("(") == shown.count(")"), f"{name}: cut inside parentheses: {shown!r}"
        assert shown.endswith(".") or shown == first, f"{name}: cut mid-sentence: {shown!r}"
    if path == ("calibrate",):
        assert "(Eq. 5) and porosity over seeds" in " ".join(listing.split())


def _section(text: str, title: str) -> list[str]:
    """The names of a help section's rows (``simulate repose`` in ``Subcommands:``)."""
    block = text.split(f"\n{title}:\n", 1)[1].split("\n\n", 1)[0]
    return [re.split(r"\s{2,}", line.strip())[0] for line in block.splitlines() if re.match(r"  \S", line)]


def test_group_help_names_every_command_subcommand_and_method(runner):
    from grainforge.methods import METHODS

    res = runner.invoke(cli, ["--help"], terminal_width=100)
    assert res.exit_code == 0
    assert _section(res.output, "Generator methods (grainforge generate METHOD)") == sorted(METHODS)
    assert set(_section(res.output, "Commands")) == set(cli.commands)
    groups = [(n, c) for n, c in cli.commands.items() if isinstance(c, click.Group) and n != "generate"]
    assert _section(res.output, "Subcommands") == sorted(f"{n} {s}" for n, c in groups
                                                         for s in [*c.commands, *getattr(c, "two_words", {})])
    assert {"simulate triaxial", "simulate calibrate", "simulate calibrate material",
            "calibrate dpa"} <= set(_section(res.output, "Subcommands"))


def test_group_help_follows_the_registries(runner, monkeypatch):
    """A method added to the registry and a subcommand added to a group appear in ``grainforge --help``:
    the listing is made from them, not written by hand."""
    from grainforge.methods import METHODS

    monkeypatch.setitem(METHODS, "zzmethod", "grainforge.methods.rf")
    extra = click.Command("zzsub", help="A subcommand added by the test.")
    monkeypatch.setitem(cli.commands["calibrate"].commands, "zzsub", extra)
    res = runner.invoke(cli, ["--help"], terminal_width=100)
    assert res.exit_code == 0
    assert "zzmethod" in _section(res.output, "Generator methods (grainforge generate METHOD)")
    assert "calibrate zzsub" in _section(res.output, "Subcommands")
    assert "A subcommand added by the test." in res.output


def test_every_option_is_declared_in_the_help_style():
    """Every option of every command is declared with ``grainforge.cli.help_style.option`` (the one help style,
    through click's public ``cls``), not a plain ``click.option`` whose help would end in click's own style."""
    from grainforge.cli.help_style import HelpOption, unstyled_options
    from grainforge.cli.main import cli

    assert unstyled_options(cli) == []
    count = cli.commands["generate"].commands["fso"].params
    assert any(isinstance(p, HelpOption) for p in count)

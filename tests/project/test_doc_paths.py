"""Every file an example command in README.md, docs/*.md and docs/guide/*.md reads exists.

A new user copies the commands of the README and the docs: each input file they
name must be in the repository (e.g. ``examples/images/micrograph.png``), or be
written by an earlier command of the same page (``--out out/cri`` before
``out/cri/*.stl``), or by ``make demo`` (the set-up every page assumes: its
virtual environment and ``out/demo``).  The commands are read with the real
``grainforge`` command tree: an argument whose type is a path and not an output
is an input; an output (``OutPath``) is what the command creates.  Other
programs create what follows ``--out``, ``--figure``, ``-o`` or ``>``, and the
target of ``python3 -m venv DIR``, ``mkdir DIR``, ``git clone URL DIR`` and
``touch FILE``.  Commands in a transcript followed by ``Error:`` show a refusal
and read nothing.  Inline code naming a file of the repository
(``examples/...``, ``benchmarks/...``) must name one that exists.

"In the repository" means a file git tracks (or would: untracked files not
ignored count), never what happens to lie on this machine: an ignored ``out/``
or ``.venv`` of earlier runs, or an absolute path (the throwaway venv of benchmarks.md),
so that the outcome is the same on a fresh clone.
"""

from __future__ import annotations

import fnmatch
import functools
import re
import shlex
import subprocess
from pathlib import Path, PurePosixPath

import click
import numpy as np
import pytest

from grainforge.cli.main import cli
from grainforge.cli.paths import OutPath

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "guide").glob("*.md"))]
SHELL_LANGS = {"", "sh", "bash", "console", "shell"}
#: a value of a non-path option that names a file (``--images a.png,b.png``, ``--spectrum fd.csv``)
FILE_SUFFIX = re.compile(r"\.(png|jpe?g|tiff?|csv|json|toml|stl|obj|ply|3mf|py)$", re.I)
REPO_DIRS = ("examples/", "docs/", "tests/", "benchmarks/", "src/")


def fenced_blocks(text: str):
    """(language, body) of every fenced code block."""
    for m in re.finditer(r"^```([\w+-]*)[^\n]*\n(.*?)^```", text, re.S | re.M):
        yield m.group(1).lower(), m.group(2)


def shell_commands(body: str) -> list[list[str]]:
    """The commands of a shell block as token lists (continuations joined, comments dropped).

    In a transcript (lines starting with ``$ ``), the other lines are output; a
    command whose output starts with ``Error:`` is a shown refusal and is left out.
    """
    lines = body.replace("\\\n", " ").splitlines()
    transcript = any(line.startswith("$ ") for line in lines)
    out = []
    for i, line in enumerate(lines):
        if transcript:
            if not line.startswith("$ "):
                continue
            following = lines[i + 1] if i + 1 < len(lines) else ""
            if following.startswith("Error:"):
                continue
            line = line[2:]
        tokens = shlex.split(line, comments=True)
        command: list[str] = []
        for tok in tokens + [";"]:  # split on && and ;, drop sub-shell parentheses
            tok = tok.strip("()")
            if tok in ("&&", ";", "||", ""):
                if command:
                    out.append(command)
                command = []
            else:
                command.append(tok)
    return out


def makefile_recipe(target: str) -> list[list[str]]:
    """The grainforge commands of a Makefile target's recipe (``$(BIN)/grainforge`` read as ``grainforge``)."""
    text = (ROOT / "Makefile").read_text()
    m = re.search(rf"^{re.escape(target)}:[^\n]*\n((?:\t[^\n]*\n?)*)", text, re.M)
    if not m:
        return []
    cmds = []
    for line in m.group(1).splitlines():
        tokens = shlex.split(line.strip().replace("$(BIN)/", ""))
        if tokens and tokens[0] == "grainforge":
            cmds.append(tokens)
    return cmds


def resolve(args: list[str]) -> tuple[click.Command, list[str]]:
    """The grainforge (sub)command ``args`` runs and its remaining arguments."""
    cmd: click.Command = cli
    args = list(args)
    while isinstance(cmd, click.Group) and args:
        two = getattr(cmd, "two_words", {}).get(" ".join(args[:2]))  # simulate calibrate material
        if two is not None:
            return two, args[2:]
        if args[0] not in cmd.commands:
            break
        cmd = cmd.commands[args.pop(0)]
    return cmd, args


def classify(args: list[str]) -> tuple[list[str], list[str]]:
    """(inputs, outputs) of a grainforge command line, by the types of its parameters."""
    cmd, rest = resolve(args)
    options = {name: p for p in cmd.params if isinstance(p, click.Option) for name in p.opts + p.secondary_opts}
    positional = [p for p in cmd.params if isinstance(p, click.Argument)]
    values: list[tuple[click.Parameter, str]] = []
    free: list[str] = []
    i = 0
    while i < len(rest):
        tok = rest[i]
        name, eq, inline = tok.partition("=")
        if tok.startswith("-") and name in options:
            p = options[name]
            if p.is_flag or p.count:
                i += 1
                continue
            if eq:
                values.append((p, inline))
                i += 1
            else:
                assert i + 1 < len(rest), f"{' '.join(args)}: {name} has no value"
                values.append((p, rest[i + 1]))
                i += 2
        else:
            assert not tok.startswith("--"), f"{' '.join(args)}: {tok} is not an option of this command"
            free.append(tok)
            i += 1
    for p in positional:
        take = free if p.nargs == -1 else free[: p.nargs]
        values += [(p, v) for v in take]
        free = [] if p.nargs == -1 else free[p.nargs:]
    inputs, outputs = [], []
    for p, v in values:
        if isinstance(p.type, OutPath):
            outputs.append(v)
        elif isinstance(p.type, click.Path):
            inputs.append(v)
        elif "://" not in v:
            inputs += [part for part in v.split(",") if FILE_SUFFIX.search(part.split("#")[0])]
    return inputs, outputs


def _norm(path: str, cwd: str = "") -> PurePosixPath:
    p = PurePosixPath(cwd) / path if cwd else PurePosixPath(path)
    parts: list[str] = []
    for part in p.parts:
        if part == "..":
            parts.pop()
        elif part != ".":
            parts.append(part)
    return PurePosixPath(*parts)


@functools.cache
def repository_paths() -> frozenset[PurePosixPath]:
    """The repository's files and their folders, relative to its root: what git tracks, and untracked files it does
    not ignore (a new page's new example before ``git add``); without git (an unpacked source archive), every file
    under the root but the ignored leftovers of runs (``out/``, the virtual environment, caches)."""
    try:
        listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                                capture_output=True, check=True).stdout.decode().split("\0")
        files = [PurePosixPath(f) for f in listed if f and (ROOT / f).exists()]
    except (OSError, subprocess.CalledProcessError):
        skip = {"out", ".venv", ".git", ".hypothesis", ".pytest_cache", ".ruff_cache", "site"}
        files = [PurePosixPath(p.relative_to(ROOT).as_posix()) for p in ROOT.rglob("*")
                 if p.is_file() and not skip & set(p.relative_to(ROOT).parts)]
    return frozenset(files) | {d for f in files for d in f.parents if str(d) != "."}


def in_repository(p: PurePosixPath) -> bool:
    """Whether the relative path ``p`` (a glob allowed, ``*`` within one folder) names something of the repository."""
    paths = repository_paths()
    if not any(c in str(p) for c in "*?["):
        return p in paths
    parts = [re.compile(fnmatch.translate(q)) for q in p.parts]
    return any(len(q.parts) == len(parts) and all(r.match(x) for r, x in zip(parts, q.parts)) for q in paths)


def available(path: str, created: set[PurePosixPath], cwd: str = "") -> bool:
    """Whether ``path`` (a glob allowed) is in the repository or under something an earlier command wrote (an
    absolute path or one in the home folder only if a command wrote it: what this machine holds there counts
    for nothing)."""
    p = _norm(path, cwd)
    if not (p.is_absolute() or path.startswith("~")) and in_repository(p):
        return True
    head = []
    for q in p.parts:  # the part of a glob before its first wildcard
        if any(c in q for c in "*?["):
            break
        head.append(q)
    base = PurePosixPath(*head) if head else PurePosixPath(".")
    return any(c == base or c in base.parents or c == p for c in created)


#: a shell variable assignment before a command (``OMP_NUM_THREADS=1 nice ...``)
ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=")


def other_program(tokens: list[str]) -> tuple[str, list[str], list[str]]:
    """(program, inputs, outputs) of a command line that is not grainforge's: the files it is given are read; it
    creates what follows ``--out``, ``--figure``, ``-o`` or ``>``, and the target of ``python -m venv DIR``,
    ``virtualenv DIR``, ``mkdir DIR``, ``git clone URL [DIR]``, ``touch FILE``.  Variable assignments before the
    program are skipped, and so is ``nice`` (the program it runs, from the venv made by make, is the program)."""
    while tokens and ASSIGNMENT.match(tokens[0]):
        tokens = tokens[1:]
    if tokens and PurePosixPath(tokens[0]).name == "nice":
        tokens = tokens[1:]
    if not tokens:
        return "", [], []
    prog, rest = PurePosixPath(tokens[0]).name, tokens[1:]
    outputs = [v for k, v in zip(rest, rest[1:]) if k in ("--out", "--figure", "-o", ">", ">>")]
    words = [t for t in rest if not t.startswith("-")]
    if prog.startswith("python") and rest[:2] == ["-m", "venv"] or prog == "virtualenv":
        outputs += words[1:] if prog.startswith("python") else words
    elif prog in ("mkdir", "touch"):
        outputs += words
    elif prog == "git" and words[:1] == ["clone"] and len(words) >= 2:
        outputs.append(words[2] if len(words) > 2 else PurePosixPath(words[1]).name.removesuffix(".git"))
    inputs = [t for t in rest if not t.startswith("-") and ("/" in t or FILE_SUFFIX.search(t)) and "://" not in t
              and t not in outputs and t not in (">", ">>")]
    return prog, inputs, outputs


def setup_created() -> set[PurePosixPath]:
    """What ``make demo`` (the set-up every page assumes) creates: its virtual environment and the demo's outputs."""
    m = re.search(r"^VENV\s*:?=\s*(\S+)", (ROOT / "Makefile").read_text(), re.M)
    created = {_norm(m.group(1))} if m else set()
    for args in makefile_recipe("demo"):
        created |= {_norm(o) for o in classify(args[1:])[1]}
    return created


def missing_in(page: Path) -> list[str]:
    """Input paths of the page's example commands that nothing provides."""
    created = setup_created()
    problems = []
    for lang, body in fenced_blocks(page.read_text()):
        if lang not in SHELL_LANGS:
            continue
        cwd = ""
        for tokens in shell_commands(body):
            prog = PurePosixPath(tokens[0]).name
            if prog == "cd":
                cwd = str(_norm(tokens[1], cwd)) if len(tokens) > 1 else ""
                continue
            if prog == "make":
                for target in tokens[1:]:
                    for args in makefile_recipe(target):
                        created |= {_norm(o) for o in classify(args[1:])[1]}
                continue
            if prog == "grainforge":
                inputs, outputs = classify(tokens[1:])
            else:  # another program (yade, a benchmark script): the files it is given, and what it creates
                _, inputs, outputs = other_program(tokens)
            problems += [f"{page.name}: `{' '.join(tokens)}` reads {i}, which nothing provides"
                         for i in inputs if not available(i, created, cwd)]
            created |= {_norm(o, cwd) for o in outputs}
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    for span in re.findall(r"`([^`\n]+)`", text):
        for tok in span.split():
            tok = tok.strip("(),;:")
            if tok.startswith(REPO_DIRS) and not in_repository(_norm(tok.split("::")[0].split("#")[0])):
                problems.append(f"{page.name}: `{span}` names {tok}, which is not in the repository")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_file_an_example_reads_exists(page):
    assert missing_in(page) == []


def test_the_checker_sees_a_missing_file_and_an_earlier_output(tmp_path):
    """The rules themselves: a made-up input is reported; an earlier --out (of grainforge or a script), a demo
    output and a repo file are not."""
    page = tmp_path / "page.md"
    page.write_text("```sh\n"
                    "grainforge fourier micrograph.png --csv fd.csv\n"
                    "grainforge generate cri --out out/x --images a.png,examples/images/grain-a.png\n"
                    "grainforge check out/x/*.stl out/y/*.stl\n"
                    "grainforge generate rf --out out/rf --spectrum fd.csv\n"
                    "grainforge plot zingg out/demo/analysis/cri.csv -o z.png\n"
                    "nice .venv/bin/python benchmarks/make_synthetic_sand.py --grains 9 --out out/big\n"
                    "nice .venv/bin/python benchmarks/fit_recovery.py --sand out/big/synthetic-angular-sand.csv\n"
                    "```\n"
                    "See `examples/no-such-recipe.toml` and `examples/cri-sand.toml`.\n")
    problems = missing_in(page)
    assert len(problems) == 4, problems
    assert [p.split(" reads ")[-1].split(",")[0] for p in problems[:3]] == ["micrograph.png", "a.png", "out/y/*.stl"]
    assert "examples/no-such-recipe.toml" in problems[3]


def test_what_a_command_creates_counts_and_this_machine_does_not(tmp_path):
    """The target of ``python3 -m venv``, ``mkdir``, ``git clone``, ``-o`` or ``>`` is provided to the commands after
    it; a file that merely lies on this machine (an absolute path, an ignored leftover of a run) is not, whether it
    exists or not; the set-up's virtual environment is, behind variable assignments and ``nice``."""
    leftover = tmp_path / "leftover.png"
    leftover.write_bytes(b"not in the repository")
    page = tmp_path / "page.md"
    page.write_text("```console\n"
                    "python3 -m venv /tmp/doc-paths-venv && /tmp/doc-paths-venv/bin/pip install x\n"
                    "grainforge fourier /tmp/doc-paths-venv/lib/a.png --csv a.csv\n"
                    "mkdir -p work/sub && grainforge check work/sub/*.stl\n"
                    "git clone https://example.org/tools.git && grainforge check tools/g.stl\n"
                    "git clone https://example.org/x.git here && grainforge check here/g.stl\n"
                    "OMP_NUM_THREADS=1 nice .venv/bin/python benchmarks/bench_scan.py --size 10 -o fig.png\n"
                    "grainforge fourier fig.png --csv b.csv\n"
                    f"grainforge fourier {leftover} --csv c.csv\n"
                    "grainforge fourier out/never-made/x.png --csv d.csv\n"
                    "```\n")
    problems = missing_in(page)
    assert [p.split(" reads ")[-1].split(",")[0] for p in problems] == [str(leftover), "out/never-made/x.png"], \
        problems
    assert not in_repository(PurePosixPath(".venv")) and not in_repository(PurePosixPath("out"))


def test_example_images_are_what_the_code_makes(tmp_path):
    """examples/images/ holds what ``grainforge.viz.demo.example_images`` writes (same pixels), and nothing else."""
    from PIL import Image

    from grainforge.viz.demo import EXAMPLE_IMAGES, example_images

    folder = ROOT / "examples" / "images"
    assert sorted(p.name for p in folder.glob("*.png")) == sorted(EXAMPLE_IMAGES)
    for made in example_images(tmp_path):
        assert np.array_equal(np.asarray(Image.open(made)), np.asarray(Image.open(folder / made.name))), made.name

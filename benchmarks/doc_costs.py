"""What the documented long commands cost: the figure the docs state, the command's own estimate, the run.

Every command in a shell block of README.md and the guides whose comment states a cost as ``≈ N s``,
``≈ N min`` or ``≈ N h`` (the time of the whole command on 2 idle cores) is run as written — only its output
(``--out``/``-o``, and ``out/…`` inputs an earlier command of its page writes, which is run first) is moved into a
temporary folder — and timed. The command's own estimate is read from its
``estimated time: [at most] about …`` line on stderr. Printed per command: the stated cost, the estimate, the
measured wall time, the CPU time of the command and its engines, and the two ratios (stated / measured and
estimate / measured). A stated cost or an estimate is meant to be within a factor of 1.5 of the run; rows
outside it are marked. Asserts nothing; docs/benchmarks.md (*What the documented commands cost*) holds the
last figures.

Usage::

    .venv/bin/python benchmarks/doc_costs.py --list              # the commands and their stated costs
    .venv/bin/python benchmarks/doc_costs.py --max-minutes 5     # run those stated at 5 min or less
    .venv/bin/python benchmarks/doc_costs.py --only "calibrate"  # those whose text contains it

Run it on an idle machine: the figures are wall times on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "guide").glob("*.md"))]
COST = re.compile(r"≈\s*([\d.]+)\s*(s|min|h)\b")
UNIT = {"s": 1.0, "min": 60.0, "h": 3600.0}
ESTIMATE = re.compile(r"estimated time: (at most )?about ([\d.e+]+) (s|min|h|days)")
#: the factor within which a stated cost and an estimate should be of the measured time
FACTOR = 1.5


def _output(tokens: list[str]) -> str | None:
    for flag in ("--out", "-o"):
        if flag in tokens:
            return tokens[tokens.index(flag) + 1].rstrip("/")
    return None


def documented() -> list[tuple[str, str, float, list[str]]]:
    """(page, command, stated seconds, earlier commands it reads from) of every shell-block command whose comment
    states a cost; the earlier ones are the same page's commands whose output the command names."""
    found = []
    for page in PAGES:
        text = page.read_text()
        before: list[str] = []
        for m in re.finditer(r"^```([\w+-]*)[^\n]*\n(.*?)^```", text, re.S | re.M):  # every block, in order
            if m.group(1).lower() not in ("", "sh", "bash", "console", "shell"):
                continue
            for line in m.group(2).replace("\\\n", " ").splitlines():
                code, _, comment = line.partition(" #")
                code = " ".join(code.split())
                if not code.startswith("grainforge "):
                    continue
                tokens = shlex.split(code)
                cost = COST.search(comment)
                if cost:
                    needs = [c for c in before if any(t.rstrip("/") == _output(shlex.split(c))
                                                      for t in tokens[1:])]
                    found.append((page.relative_to(ROOT).as_posix(), code,
                                  float(cost.group(1)) * UNIT[cost.group(2)], needs))
                before.append(code)
    return found


def relocated(command: str, folder: Path) -> list[str]:
    """The command's tokens with its output (``--out``/``-o``), and any earlier output it reads, in ``folder``;
    the grainforge of this Python."""
    tokens = shlex.split(command)
    for k, tok in enumerate(tokens):
        if tok.startswith("out/"):
            tokens[k] = str(folder / tok)
    for flag in ("--out", "-o"):
        if flag in tokens:
            k = tokens.index(flag) + 1
            tokens[k] = str(folder / tokens[k].lstrip("/"))
    return [sys.executable, "-c", "from grainforge.cli.main import main; main()", *tokens[1:]]


def run(command: str, needs: list[str]) -> dict:
    """Run one documented command (after the earlier ones it reads from, not timed); its wall and CPU seconds,
    its estimate and exit status."""
    with tempfile.TemporaryDirectory(prefix="doc-costs-") as tmp:
        for earlier in needs:
            subprocess.run(relocated(earlier, Path(tmp)), cwd=ROOT, stdin=subprocess.DEVNULL, capture_output=True,
                           check=True)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        r = subprocess.run(relocated(command, Path(tmp)), cwd=ROOT, stdin=subprocess.DEVNULL,
                           capture_output=True, text=True)
        wall = time.perf_counter() - t
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    est = ESTIMATE.search(r.stderr)
    estimate = float(est.group(2)) * {**UNIT, "days": 86400.0}[est.group(3)] if est else float("nan")
    return {"wall": wall, "cpu": (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime),
            "estimate": estimate, "bound": bool(est and est.group(1)), "exit": r.returncode,
            "last": (r.stderr.strip().splitlines() or [""])[-1] if r.returncode else ""}


def _fmt(seconds: float) -> str:
    if seconds != seconds:
        return "—"
    return f"{seconds / 60:.1f} min" if seconds >= 90 else f"{seconds:.0f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="list the commands and their stated costs, run nothing")
    ap.add_argument("--max-minutes", type=float, default=None, help="run only those stated at this or less")
    ap.add_argument("--only", default=None, help="run only those whose text contains this")
    args = ap.parse_args()
    rows = documented()
    if args.only:
        rows = [r for r in rows if args.only in r[1]]
    if args.max_minutes is not None:
        rows = [r for r in rows if r[2] <= 60 * args.max_minutes]
    if args.list:
        for page, command, stated, needs in rows:
            print(f"{_fmt(stated):>9}  {page}: {command}" + (f"  (after: {'; '.join(needs)})" if needs else ""))
        return
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("| command | page | stated | estimate | wall | CPU | stated/wall | estimate/wall | exit |")
    print("|---|---|---|---|---|---|---|---|---|")
    for page, command, stated, needs in rows:
        m = run(command, needs)
        ratio_s, ratio_e = stated / m["wall"], m["estimate"] / m["wall"]
        flag = lambda x: "" if 1 / FACTOR <= x <= FACTOR else " ✗"  # noqa: E731
        est = ("≤ " if m["bound"] else "") + _fmt(m["estimate"])
        print(f"| `{command}` | {page} | {_fmt(stated)} | {est} | {_fmt(m['wall'])} | {_fmt(m['cpu'])} | "
              f"{ratio_s:.2f}{flag(ratio_s)} | {ratio_e:.2f}{flag(ratio_e) if ratio_e == ratio_e else ''} | "
              f"{m['exit']}{': ' + m['last'][:80] if m['last'] else ''} |", flush=True)
    print(f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()

"""A material calibration from Python, as ``grainforge simulate calibrate material`` runs it: the contact friction
μ and the rolling resistance μ_r fitted together to several measured angles (a tilt angle and a triaxial friction
angle, say).

:func:`calibrate_material` runs the steps of :func:`grainforge.simulate.calibration.calibrate_friction` (checks,
journal, estimate, templates, staged outputs) around the surrogate-model search of
:func:`grainforge.simulate.surrogate.search_material`: each point (μ, μ_r) runs every target's test, every seed.
It writes ``calibration.csv`` (every run), ``calibration.json`` (the result and the settings),
``calibration.png`` (the misfit map), ``templates-<test>.csv`` and every run (``runs/``), and returns a
:class:`MaterialCalibration`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import InputError
from .surrogate import DEFAULT_SD, Target

__all__ = ["MaterialCalibration", "PointEvaluated", "parse_target", "check_targets", "material_outputs",
           "material_record", "material_figure", "material_line", "calibrate_material", "FRICTION_RANGE",
           "ROLLING_FRICTION_RANGE"]

#: the default bounds of μ and of μ_r
FRICTION_RANGE = (0.1, 1.5)
ROLLING_FRICTION_RANGE = (0.0, 0.5)
#: the columns of calibration.csv: every test's, and a triaxial run's own
COLUMNS = ("point", "friction", "rolling_friction", "test", "seed", "angle_deg", "label", "grains", "inserted", "lost",
           "steps", "dt_s", "simulated_time_s", "note")
TRIAXIAL_COLUMNS = ("peak_friction_deg", "ultimate_friction_deg", "max_dilatancy_deg", "packing",
                    "initial_void_ratio", "problems")


@dataclass(frozen=True)
class PointEvaluated:
    """A point of a material calibration run: its index, μ, μ_r, each test's seed-averaged angle (degrees) and
    its runs' rows."""

    point: int
    friction: float
    rolling_friction: float
    angles: dict
    rows: tuple


@dataclass(frozen=True)
class MaterialCalibration:
    """A finished material calibration (:func:`calibrate_material`); its outputs are in ``out``.

    Attributes
    ----------
    targets : tuple of Target
        The angles reached for, by test.
    out : Path
        The output folder (``calibration.json`` holds :attr:`record`).
    friction, rolling_friction : float
        The best (μ, μ_r): least predicted misfit.
    friction_bounds, rolling_friction_bounds : (float, float)
        Their uncertainty: the extent of the region within the noise of the best.
    reached : bool
        Whether the targets are reached together (the best misfit within the noise); False: no fit in the bounds.
    converged : bool
        Whether the search stopped on its rule before the budget was spent.
    search : MaterialSearch
        The search (every point, the surrogates on the grid).
    rows : tuple of dict
        Every run's row (``calibration.csv``).
    record : dict
        ``calibration.json``'s record.
    commands : dict
        The ``grainforge simulate TEST`` command that uses (μ, μ_r), by test.
    line : str
        The line the command prints.
    failed_runs : tuple of str
        The runs that fail their own check (a triaxial run's problems).
    clump_warning : str or None
        With ``clump_accuracy``: the clumps that miss it.
    """

    targets: tuple
    out: Path
    friction: float
    rolling_friction: float
    friction_bounds: tuple
    rolling_friction_bounds: tuple
    reached: bool
    converged: bool
    search: object
    rows: tuple
    record: dict
    commands: dict
    line: str
    failed_runs: tuple
    clump_warning: str | None

    @property
    def passed(self) -> bool:
        """Whether the targets are reached and every run and clump passes its own check (else the command exits 3)."""
        return self.reached and not self.failed_runs and not self.clump_warning


def parse_target(text: str) -> Target:
    """A target from the command line's ``TEST=ANGLE`` or ``TEST=ANGLE:SD`` (degrees; SD default 1).

    Parameters
    ----------
    text : str
        E.g. ``"tilt=38"`` or ``"triaxial=37:1.5"``.

    Returns
    -------
    Target

    Raises
    ------
    grainforge.errors.InputError
        Text not of that form.

    Examples
    --------
    >>> parse_target("tilt=38"), parse_target("triaxial=37:1.5")
    (Target(name='tilt', angle=38.0, sd=1.0), Target(name='triaxial', angle=37.0, sd=1.5))
    """
    name, sep, value = text.partition("=")
    angle, _, sd = value.partition(":")
    try:
        return Target(name.strip(), float(angle), float(sd) if sd else DEFAULT_SD)
    except ValueError:
        raise InputError(f"{{targets}}: {text!r} is not TEST=ANGLE or TEST=ANGLE:SD (degrees)",
                         setting="targets") from None


def check_targets(targets: Sequence[Target], angle: str | None = None) -> tuple[Target, ...]:
    """Refuse, in one line, a target of an unknown test, a test given twice, an angle out of range or a spread
    that is no positive number.

    Parameters
    ----------
    targets : sequence of Target
        The targets.
    angle : {"ultimate", "peak"}, optional
        A triaxial target's friction angle (only with a triaxial target).

    Returns
    -------
    tuple of Target
        The targets.

    Raises
    ------
    grainforge.errors.InputError
        The first refusal.
    """
    from .friction_search import check_target

    tests = ("tilt", "repose", "triaxial")
    targets = tuple(targets)
    if len(targets) < 1:
        raise InputError("{targets}: give at least one TEST=ANGLE", setting="targets")
    seen = set()
    for t in targets:
        if t.name not in tests:
            raise InputError(f"{{targets}}: unknown test {t.name!r} (one of {', '.join(tests)})", setting="targets")
        if t.name in seen:
            raise InputError(f"{{targets}}: {t.name} is given twice", setting="targets")
        seen.add(t.name)
        check_target(t.angle)
        if not (math.isfinite(t.sd) and t.sd > 0):
            raise InputError(f"{{targets}}: the spread of {t.name} must be a positive number of degrees, got "
                             f"{t.sd:g}", setting="targets")
    if angle is not None and "triaxial" not in seen:
        raise InputError("{angle} is a triaxial target's: give --target triaxial=A with it", setting="angle")
    return targets


def material_outputs(out: str | os.PathLike, tests: Sequence[str], clump_accuracy: float | None = None) -> list[Path]:
    """The paths a material calibration writes into ``out`` (refused when they exist, without ``overwrite``).

    Parameters
    ----------
    out : path
        The output folder.
    tests : sequence of str
        The targets' tests (one ``templates-<test>.csv`` each).
    clump_accuracy : float, optional
        With an accuracy target, ``clumps-<test>.csv`` too.

    Returns
    -------
    list of Path
        The outputs.
    """
    out = Path(out)
    paths = [out / n for n in ("calibration.csv", "calibration.json", "calibration.png", "runs")]
    paths += [out / f"templates-{t}.csv" for t in tests]
    return paths + [out / f"clumps-{t}.csv" for t in tests] * (clump_accuracy is not None)


def _prepare(opts: dict, stack: ExitStack, out, outputs, search: dict):
    """Every step before the engine runs (as :func:`grainforge.simulate.pipeline._prepare`, one set of templates
    per test): ``(out, journal, executor, workers, {test: (chosen, templates)})``."""
    from ..runtime.workers import default_workers
    from .pipeline import Count, Estimate, Note, _check_out, _engine_runners, check_installed
    from .specimen import build_population, check_inputs, choose_grains
    from .sweep import open_journal, sweep_fingerprint

    first = next(iter(opts.values()))
    out = _check_out(out, outputs, first.overwrite)
    extra = {f"{t}_settings": sweep_fingerprint(t, (), o.settings) for t, o in opts.items()}
    fingerprint = sweep_fingerprint("calibrate material", first.inputs, first.settings, engine=first.engine,
                                    mpi=first.mpi, shape=first.shape, spacing=first.spacing,
                                    as_spheres=first.as_spheres, clump_accuracy=first.clump_accuracy, **search, **extra)
    journal = open_journal(out, fingerprint, resume=first.resume, overwrite=first.overwrite)
    available, make_seconds = check_inputs(first.inputs)
    pool = {t: min(available, 4 * o.settings.templates) if o.quick else None for t, o in opts.items()}
    executor, workers = _engine_runners(first, stack)
    seconds, most = _estimate(opts, search["budget"], available=available, make_seconds=make_seconds, pool=pool,
                              workers=workers)
    if executor is None:
        check_installed(first.engine, first.mpi)
    first.say(Estimate(seconds, most))
    made, say, cache = {}, first.say, {}
    for t, o in opts.items():  # tests whose templates' settings agree share them (chosen and made once)
        key = (o.settings.templates, o.settings.size, pool[t])
        if key not in cache:
            cache[key] = choose_grains(o.inputs, o.settings, pool=pool[t],
                                       workers=workers if executor is None else default_workers(),
                                       progress=lambda done, total: say(Count("grains", done, total)))
        chosen = cache[key]
        o.say(Note(f"{t}: " + chosen.summary() + f"; templates-{t}.csv"))
        made_key = key + (o.settings.spheres, o.settings.density)
        if made_key not in cache:
            what = "clumps" if o.shape == "clump" else "level sets"
            cache[made_key] = build_population(
                o.inputs, o.settings, as_spheres=o.as_spheres, shape=o.shape, spacing=o.spacing, chosen=chosen,
                progress=lambda done, total, w=what: say(Count(w, done, total)),
                **({} if o.clump_accuracy is None else {"clump_accuracy": o.clump_accuracy}))
        made[t] = (chosen, cache[made_key])
    first.say(Estimate(seconds, most, inputs_read=True))
    return out, journal, executor, workers, made


def _estimate(opts: dict, budget: int, *, available, make_seconds, pool, workers) -> tuple[float, float]:
    """The seconds of ``budget`` points of every test (usual, and longest: a triaxial compaction to its time limit),
    the templates once per test; refuse a calibration beyond the limit (one line naming ``budget``)."""
    from ..runtime.estimate import SECONDS_LIMIT, TooLargeError, _limit, duration
    from .settings import check_size
    from .specimen import template_make_seconds

    usual = most = 0.0
    for t, o in opts.items():
        size = dict(available=available, make_seconds=template_make_seconds(o.settings.templates, available,
                                                                             make_seconds, pool[t]),
                    as_spheres=o.as_spheres, workers=workers, shape=o.shape, spacing=o.spacing, engine=o.engine)
        make = check_size(t, replace(o.settings, seeds=1, grains=2), **size)
        usual += make + (check_size(t, o.settings, **size) - make) * budget
        most += make + (check_size(t, o.settings, longest=True, **size) - make) * budget
    if most > SECONDS_LIMIT:
        raise TooLargeError(f"a material calibration of up to {budget} points × {', '.join(opts)} would take about "
                            f"{duration(most)} of computing (limit {_limit()}); lower {{budget}}, {{grains}} or "
                            "{seeds}", setting=("budget", "grains", "seeds"))
    return usual, most


def _point_runs(opts: dict, made: dict, stage: Path, job: dict, angle: str | None, rows: list):
    """``angles_of(k, μ, μ_r)`` of the search: every test's seeds at the point, into ``stage/runs/p<k>-...``."""
    from .engine import run_test, summarise
    from .friction_search import _write_curves, calibrated_angle
    from .pipeline import RunProgress

    say = next(iter(opts.values())).say

    def angles_of(k: int, mu: float, mr: float) -> dict:
        folder = stage / "runs" / f"p{k:02d}-mu{mu:.4f}-mur{mr:.4f}"
        got_all, means = [], {}
        for t, o in opts.items():
            column, _ = calibrated_angle(t, angle if t == "triaxial" else None)
            s = replace(o.settings, friction=mu, rolling_friction=mr)
            got = run_test(t, made[t][1], settings=s, out=folder, label=o.label, workers=job["workers"],
                           engine=o.engine, mpi=o.mpi, executor=job["executor"], journal=job["journal"],
                           progress=lambda i, f, p, t=t: say(RunProgress(i, f, f"{t}: {p}", evaluation=k)))
            if t == "triaxial":
                _write_curves(folder, got)
            got = [{"point": k, "friction": mu, "rolling_friction": mr, **r, "test": t, "angle_deg": float(r[column])}
                   for r in got]
            got_all += got
            means[t] = summarise(got)["angle_mean_deg"]
        rows.extend(got_all)
        say(PointEvaluated(k, mu, mr, means, tuple(got_all)))
        return {t: [r["angle_deg"] for r in got_all if r["test"] == t] for t in opts}

    return angles_of


def _wide(bounds, searched) -> bool:
    return bounds[1] - bounds[0] > 0.5 * (searched[1] - searched[0])


def _span(bounds) -> str:
    return f"{bounds[0]:.3g}–{bounds[1]:.3g}"


def material_record(search, rows: Sequence[dict], *, targets: Sequence[Target], settings: Mapping, commands: dict,
                    friction_range, rolling_friction_range, budget: int, initial_points: int,
                    angle: str | None = None) -> dict:
    """The ``calibration.json`` record of a material calibration: the best (μ, μ_r), their region, each target's
    measured and predicted angle there, the search's settings and the runs.

    Parameters
    ----------
    search : MaterialSearch
        The finished search (:func:`grainforge.simulate.surrogate.search_material`).
    rows : sequence of dict
        Every run's row.
    targets : sequence of Target
        The targets.
    settings : mapping
        Each test's settings, recorded without ``friction`` and ``rolling_friction``.
    commands : dict
        The command that uses (μ, μ_r), by test.
    friction_range, rolling_friction_range, budget, initial_points, angle
        The search's bounds, its most points, its initial design and a triaxial target's angle.

    Returns
    -------
    dict
        The record (angles in degrees).
    """
    from ..params import as_dict
    from .friction_search import calibrated_angle, failed_calibration_runs
    from .surrogate import GRID, KAPPA, REGION_DELTA

    described = []
    for t in targets:
        column, name = calibrated_angle(t.name, angle if t.name == "triaxial" else None)
        mean, sd = search.predicted[t.name]
        described.append({"test": t.name, "angle": name, "angle_column": column, "target_angle_deg": t.angle,
                          "target_sd_deg": t.sd, "predicted_angle_deg": mean, "predicted_sd_deg": sd,
                          "seed_sd_deg": search.noise_sd[t.name]})
    return {
        "targets": described, "friction": search.friction, "rolling_friction": search.rolling_friction,
        "friction_bounds": list(search.friction_bounds),
        "rolling_friction_bounds": list(search.rolling_friction_bounds), "misfit": search.misfit,
        "misfit_threshold": search.threshold, "reached": search.reached, "converged": search.converged,
        "points": len(search.points), "runs": len(rows), "budget": budget, "initial_points": initial_points,
        "friction_range": list(friction_range), "rolling_friction_range": list(rolling_friction_range),
        "method": (f"a Latin hypercube of {initial_points} points, then points of least optimistic misfit (each "
                   f"residual shrunk by {KAPPA:g} posterior sd) of one Gaussian process per target (scikit-learn; "
                   f"constant × RBF + white noise, fitted to every seed's angle) on a {GRID}×{GRID} grid; misfit "
                   "Σ((predicted − target)/target_sd)²; reached when the best misfit ≤ misfit_threshold (χ² 95 %, "
                   "one degree per target)"),
        "uncertainty": ("friction_bounds, rolling_friction_bounds: the extent of the grid points whose misfit, "
                        "each target_sd widened by the posterior sd there, is at most misfit_threshold (or within "
                        f"{REGION_DELTA:g} of the best's, when larger)"),
        "settings": {t: {k: v for k, v in as_dict(s).items() if k not in ("friction", "rolling_friction")}
                     for t, s in settings.items()},
        "commands": commands, "failed_runs": failed_calibration_runs(rows),
    }


def material_line(record: dict, label: str, out: str | os.PathLike) -> str:
    """The line a finished material calibration prints: (μ, μ_r) with their ranges and each target, or that the
    targets are not reached together in the bounds.

    Parameters
    ----------
    record : dict
        ``calibration.json``'s record (:func:`material_record`).
    label : str
        The population's name.
    out : path
        The output folder.

    Returns
    -------
    str
        The line.
    """
    angles = " and ".join(f"{t['test']} {t['predicted_angle_deg']:.1f}°" for t in record["targets"])
    wanted = " and ".join(f"{t['test']} {t['target_angle_deg']:g}°" for t in record["targets"])
    runs = f"({record['points']} points, {record['runs']} runs); {Path(out) / 'calibration.json'}"
    where = f"friction {record['friction']:.3f}, rolling friction {record['rolling_friction']:.3f}"
    if not record["reached"]:
        unsure = [t for t in record["targets"] if t["predicted_sd_deg"] > t["target_sd_deg"]]
        why = (f"; the surrogate is still unsure there (± {max(t['predicted_sd_deg'] for t in unsure):.1f}°): "
               f"more points (budget) may reach them" if unsure else "")
        return (f"{label}: {wanted} are not reached together with friction in {_span(record['friction_range'])} "
                f"and rolling friction in {_span(record['rolling_friction_range'])}: the closest point, {where}, "
                f"gives {angles} (misfit {record['misfit']:.3g} > {record['misfit_threshold']:.3g}){why} {runs}")
    note = "" if record["converged"] else f" (budget of {record['budget']} points spent)"
    wide = [n for n in ("friction", "rolling_friction") if _wide(record[f"{n}_bounds"], record[f"{n}_range"])]
    if wide:
        note += (f"; the region within the noise spans over half the {' and '.join(w.replace('_', ' ') for w in wide)}"
                 " range: more points or another target would narrow it")
    return (f"{label}: friction {record['friction']:.3f} ({_span(record['friction_bounds'])}), rolling friction "
            f"{record['rolling_friction']:.3f} ({_span(record['rolling_friction_bounds'])}) reach {wanted} "
            f"(predicted {angles}){note} {runs}")


def material_figure(search, targets: Sequence[Target], caption: str | None = None):
    """The misfit map over (μ, μ_r): the predicted misfit, each target's line (its predicted angle equal to the
    target), the uncertainty region, every point run and the best.

    Parameters
    ----------
    search : MaterialSearch
        The finished search.
    targets : sequence of Target
        The targets.
    caption : str, optional
        The line above the plot (:func:`grainforge.simulate.results.figure_caption`).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .results import add_caption

    g = search.grid
    fig, ax = plt.subplots(figsize=(6.8, 6.0), dpi=120)
    field = ax.contourf(g["friction"], g["rolling_friction"], np.log10(1.0 + g["misfit"]), levels=20, cmap="viridis_r")
    fig.colorbar(field, ax=ax, label="log₁₀(1 + predicted misfit)")
    ax.contour(g["friction"], g["rolling_friction"], np.log10(1.0 + g["misfit"]),
               levels=[math.log10(1.0 + search.threshold)], colors="white", linewidths=1.0, linestyles="dotted")
    ax.plot([], [], ":", color="0.6", lw=1.0, label=f"misfit within the noise (≤ {search.threshold:.3g})")
    for k, t in enumerate(targets):
        ax.contour(g["friction"], g["rolling_friction"], g["means"][t.name], levels=[t.angle], colors=f"C{k + 1}",
                   linewidths=1.6)
        ax.plot([], [], color=f"C{k + 1}", lw=1.6, label=f"{t.name} predicted = {t.angle:g}°")
    ax.contour(g["friction"], g["rolling_friction"], g["region"].astype(float), levels=[0.5], colors="k",
               linewidths=1.0, linestyles="dashed")
    ax.plot([], [], "k--", lw=1.0, label="uncertainty region")
    pts = search.points
    ax.plot([p.friction for p in pts], [p.rolling_friction for p in pts], "o", mfc="white", mec="k", ms=5,
            label=f"points run ({len(pts)})")
    for p in pts:
        ax.annotate(str(p.index), (p.friction, p.rolling_friction), xytext=(3, 3), textcoords="offset points",
                    fontsize=7)
    mark = "best (reached)" if search.reached else "closest (not reached)"
    ax.plot([search.friction], [search.rolling_friction], "*", color="C3", mec="k", ms=15,
            label=f"{mark}: μ {search.friction:.3f}, μ_r {search.rolling_friction:.3f}")
    ax.set_xlabel("contact friction μ")
    ax.set_ylabel("rolling resistance μ_r")
    wanted = ", ".join(f"{t.name} {t.angle:g}°" for t in targets)
    ax.set_title(f"material calibration on {wanted}: misfit map", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.55, -0.12), ncol=2, frameon=False)
    add_caption(fig, caption)
    return fig


def _write(stage: Path, search, rows: list, record: dict, targets, caption: str | None) -> None:
    """``calibration.csv``, ``calibration.json`` and ``calibration.png`` into the stage."""
    import json

    from ..io import save_figure, write_csv

    keep = COLUMNS + TRIAXIAL_COLUMNS if any(t.name == "triaxial" for t in targets) else COLUMNS
    write_csv(stage / "calibration.csv", [{k: r.get(k, "") for k in keep} for r in rows])
    (stage / "calibration.json").write_text(json.dumps(record, indent=1) + "\n")
    save_figure(material_figure(search, targets, caption), stage / "calibration.png", description=caption)


def _finish(stage: Path, opts: dict, made: dict, out: Path, journal) -> str | None:
    """Each test's ``templates-<test>.csv`` (and ``clumps-<test>.csv``), then every output moved into ``out``
    together; the clump warning line (None without one)."""
    from ..runtime.staging import signals_held
    from .run_folders import commit_stage

    warnings = []
    for t, o in opts.items():
        chosen, templates = made[t]
        chosen.write_csv(stage / f"templates-{t}.csv")
        if o.clump_accuracy is not None:
            from ..dem.clump import clump_table
            from ..dem.deck import template_record
            from ..dem.template import accuracy_warning

            (stage / f"clumps-{t}.csv").write_text(clump_table([template_record(g) for g in templates]))
            warning = accuracy_warning(templates, o.settings.spheres, out / f"clumps-{t}.csv")
            warnings += [warning] if warning else []
    with signals_held():
        commit_stage(stage, out, overwrite=next(iter(opts.values())).overwrite)
        journal.remove()
    return "; ".join(warnings) or None


def _targets(targets) -> tuple[Target, ...]:
    """Targets given as Target, ``TEST=ANGLE[:SD]`` text or a mapping of test to angle."""
    if isinstance(targets, Mapping):
        return tuple(Target(k, float(v)) for k, v in targets.items())
    return tuple(t if isinstance(t, Target) else parse_target(str(t)) for t in targets)


def calibrate_material(inputs: Sequence[str | os.PathLike], *, out: str | os.PathLike, targets, settings: Mapping,
                       angle: str | None = None, friction_range: tuple[float, float] = FRICTION_RANGE,
                       rolling_friction_range: tuple[float, float] = ROLLING_FRICTION_RANGE, budget: int = 16,
                       initial_points: int | None = None, given: Mapping | None = None, engine: str = "yade",
                       mpi: int | None = None, workers: int | None = None, scheduler: str | None = None,
                       shape: str = "clump", as_spheres: bool = False, clump_accuracy: float | None = None,
                       quick: bool = False, resume: bool = False, overwrite: bool = False, label: str | None = None,
                       progress: Callable[[object], None] | None = None) -> MaterialCalibration:
    """Fit the contact friction μ and the rolling resistance μ_r together to several measured angles, as
    ``grainforge simulate calibrate material``.

    A surrogate-model search (:func:`grainforge.simulate.surrogate.search_material`): each point runs every
    target's test, every seed; every output appears in ``out`` together, or none.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files (mm), run folders, manifests, or one TOML recipe.
    out : path
        The output folder (made).
    targets : sequence of Target or str, or mapping of str to float
        The angles to reach, each test (tilt, repose, triaxial) once: ``Target("tilt", 38.0, sd=1.0)``,
        ``"tilt=38"`` or ``"tilt=38:1.5"`` (degrees; the spread σ_target, default 1°), or ``{"tilt": 38.0}``.
    settings : mapping of str to Settings or TriaxialSettings
        Each target test's settings (:func:`grainforge.simulate.pipeline.settings_for`); μ and μ_r are fitted.
    angle : {"ultimate", "peak"}, optional
        A triaxial target's friction angle (default ultimate).
    friction_range, rolling_friction_range : (float, float)
        The bounds of μ (0 ≤ low < high ≤ 5) and of μ_r (0 ≤ low < high ≤ 1).
    budget, initial_points : int
        The most points run, and those of the initial design (2 ≤ initial_points ≤ budget; default 6, at most
        ``budget``).
    given : mapping, optional
        The settings given by name, repeated in the commands that use (μ, μ_r).
    engine, mpi, workers, scheduler, shape, as_spheres, clump_accuracy, quick, resume, overwrite, label
        As :func:`grainforge.simulate.pipeline.run_virtual_test` (``shape`` clump only: μ_r acts at spheres).
    progress : callable, optional
        Called with each ``Estimate``, ``Note``, ``Count``, ``RunProgress`` (its ``evaluation`` the point) and,
        after each point, :class:`PointEvaluated`.

    Returns
    -------
    MaterialCalibration
        (μ, μ_r), their region, whether the targets are reached, every point and run, the line and the commands.

    Raises
    ------
    grainforge.errors.InputError
        Targets, bounds, a budget or options refused (one line naming the setting); ``resume`` with other
        settings; a calibration beyond the time limit.
    FileExistsError, FileNotFoundError, EngineFailed, grainforge.runtime.cluster.SchedulerLost
        As :func:`~grainforge.simulate.pipeline.run_virtual_test`.
    grainforge.simulate.calibration.CalibrationFailed
        An angle could not be measured (nothing kept).
    """
    from .pipeline import _options
    from .surrogate import check_search

    targets = check_targets(_targets(targets), angle)
    initial_points = min(6, int(budget)) if initial_points is None else initial_points
    check_search(targets, friction_range=friction_range, rolling_range=rolling_friction_range, budget=int(budget),
                 initial=int(initial_points))
    if shape != "clump":
        raise InputError("{shape}: μ_r acts at sphere contacts: a material calibration runs clumps (--shape clump)",
                         setting="shape")
    missing = [t.name for t in targets if t.name not in settings]
    if missing:
        raise InputError(f"{{settings}}: none given for the {' and '.join(missing)} test", setting="settings")
    opts = {t.name: _options(t.name, inputs, replace(settings[t.name], rolling_friction=rolling_friction_range[1]),
                             engine=engine, mpi=mpi, workers=workers, scheduler=scheduler, shape=shape,
                             as_spheres=as_spheres, clump_accuracy=clump_accuracy, quick=quick, resume=resume,
                             overwrite=overwrite, label=label, progress=progress) for t in targets}
    search = dict(targets=[[t.name, t.angle, t.sd] for t in targets], friction_range=list(friction_range),
                  rolling_friction_range=list(rolling_friction_range), budget=int(budget),
                  initial_points=int(initial_points), **({"angle": angle or "ultimate"} if "triaxial" in opts else {}))
    with ExitStack() as stack:
        prepared = _prepare(opts, stack, out, material_outputs(out, list(opts), clump_accuracy), search)
        return _stages(opts, prepared, targets, search, dict(given or {}))


def _commands(opts: dict, given: dict, mu: float, mr: float) -> dict:
    """The ``grainforge simulate TEST`` command that uses (μ, μ_r), by test (its own settings given)."""
    from dataclasses import fields

    from .calibration import use_command

    out = {}
    for t, o in opts.items():
        own = {f.name for f in fields(o.settings)} - {"friction", "rolling_friction"}
        mine = {"rolling_friction": f"{mr:.3g}", **{k: v for k, v in given.items() if k in own}}
        out[t] = use_command(t, o.inputs, friction=mu, given=mine, quick=o.quick, as_spheres=o.as_spheres,
                             shape=o.shape, engine=o.engine, mpi=o.mpi, clump_accuracy=o.clump_accuracy)
    return out


def _stages(opts: dict, prepared, targets, search: dict, given: dict) -> MaterialCalibration:
    """The search's engine runs and the calibration's files in a staging folder, then moved into the folder."""
    from types import SimpleNamespace

    from .calibration import CalibrationFailed
    from .pipeline import _engine_errors
    from .results import figure_caption
    from .run_folders import staged
    from .surrogate import search_material
    from .sweep import JournalMismatch

    out, journal, executor, workers, made = prepared
    first = next(iter(opts.values()))
    rows: list[dict] = []
    with staged(out) as stage:
        job = {"workers": workers, "executor": executor, "journal": journal.bind(stage)}
        angles_of = _point_runs(opts, made, stage, job, search.get("angle"), rows)
        try:
            with _engine_errors(stage, SimpleNamespace(out=out, journal=journal)):
                found = search_material(angles_of, targets, friction_range=tuple(search["friction_range"]),
                                        rolling_friction_range=tuple(search["rolling_friction_range"]),
                                        budget=search["budget"], initial_points=search["initial_points"],
                                        rng=first.settings.seed)
        except JournalMismatch:  # --resume: a kept run's deck is not this one's (the user's to decide)
            raise
        except InputError as exc:  # an angle that could not be measured
            journal.remove()
            raise CalibrationFailed(f"{exc}; nothing kept") from None
        commands = _commands(opts, given, found.friction, found.rolling_friction)
        record = material_record(found, rows, targets=targets, settings={t: o.settings for t, o in opts.items()},
                                 commands=commands, friction_range=search["friction_range"],
                                 rolling_friction_range=search["rolling_friction_range"], budget=search["budget"],
                                 initial_points=search["initial_points"], angle=search.get("angle"))
        t0 = targets[0].name
        caption = figure_caption(t0, first.settings, templates=made[t0][1], label=first.label, engine=first.engine,
                                 mpi=first.mpi, rows=[r for r in rows if r["test"] == t0], friction=False)
        _write(stage, found, rows, record, targets, caption)
        warning = _finish(stage, opts, made, out, journal)
    return MaterialCalibration(targets, out, found.friction, found.rolling_friction, found.friction_bounds,
                               found.rolling_friction_bounds, found.reached, found.converged, found, tuple(rows),
                               record, commands, material_line(record, first.label, out),
                               tuple(record["failed_runs"]), warning)

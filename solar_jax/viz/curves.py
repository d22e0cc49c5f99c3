"""Learning curves: mean and 95% confidence interval over seeds, per suite and method.

A run's curve is its mean return over the suite's training morphologies (and, beside
it, over the held-out ones: zero-shot) against counted env steps, or against the run's
own seconds (``x=wall``: compiles, rounds and evaluations summed, as its summary's wall
time), which compares schedules that spend a step differently. Seeds log at
different env steps, so each run's curve is linearly interpolated onto a common grid
before averaging (``solar_jax.viz.stats.on_grid``). With fewer than ``BAND_SEEDS`` seeds
the interval says little and the grid smooths peaks away, so each seed is drawn as
logged instead.
"""

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from solar_jax.viz.figures import colour, new_figure, save
from solar_jax.viz.runs import Run, VizError, group_runs, suite_name
from solar_jax.viz.stats import mean_ci, on_grid

Metric = Literal["eval", "episode"]
METRICS: dict[str, tuple[str, str]] = {
    "eval": ("eval", "deterministic evaluation return"),
    "episode": ("round", "per-round exploration episode return (noisy, as the paper logs)"),
}
"""metric -> (record kind, what it is)."""

Axis = Literal["steps", "wall"]
AXES: dict[str, str] = {
    "steps": "env steps",
    "wall": "wall seconds (compile, collection, evaluation, updates)",
}
"""x -> its axis label: counted env steps, or the run's own seconds up to each record."""

BAND_SEEDS = 4
"""Seeds from which a line is drawn as its mean and 95% band rather than seed by seed."""

_SPLITS = (("train", "training morphologies"), ("heldout", "held-out morphologies (zero-shot)"))


def curve(
    run: Run, metric: Metric, split: str, x: Axis = "steps"
) -> tuple[np.ndarray, np.ndarray] | None:
    """(env steps or wall seconds, return) of one run: ``<metric>/<split>_return`` (split:
    train or heldout) from its records of the metric's kind; None where it has none."""
    return _series(run, metric, f"{metric}/{split}_return", x)


def _series(run: Run, metric: Metric, key: str, x: Axis) -> tuple[np.ndarray, np.ndarray] | None:
    """(env steps or wall seconds, ``key``) of the run's records of the metric's kind."""
    kind, _ = METRICS[metric]
    pairs = zip(run.records, wall_seconds(run.records), strict=True)
    chosen = [(r, w) for r, w in pairs if r.get("kind") == kind and key in r]
    if not chosen:
        return None
    at = [w if x == "wall" else r["env_steps"] for r, w in chosen]
    return np.array(at, dtype=np.float64), np.array([r[key] for r, _ in chosen], np.float64)


def wall_seconds(records: Sequence[dict]) -> np.ndarray:
    """[len(records)] the run's seconds up to the end of each record: its compiles,
    rounds (collection and updates) and evaluations summed, as the summary's wall time."""
    parts = ("perf/compile_s", "perf/round_s", "perf/eval_s")
    return np.cumsum([sum(r.get(p, 0.0) for p in parts) for r in records])


def _training_curve(run: Run, metric: Metric, x: Axis) -> tuple[np.ndarray, np.ndarray]:
    found = curve(run, metric, "train", x)
    if found is None:
        what = "evaluation" if metric == "eval" else "training round"
        raise VizError(f"{run.path}: no {what} records yet (metric={metric})")
    return found


@dataclasses.dataclass(frozen=True)
class Line:
    """One line of a panel: a (method, varying config) group's mean over its seeds."""

    suite: str
    split: str  # "train" or "heldout"
    label: str
    steps: np.ndarray  # [T] the common grid
    mean: np.ndarray  # [T]
    low: np.ndarray  # [T] 95% CI; equal to mean for one seed
    high: np.ndarray
    seeds: int
    runs: tuple[tuple[np.ndarray, np.ndarray], ...]  # each seed's (env steps, return) as logged


def curve_lines(runs: Sequence[Run], metric: Metric = "eval", x: Axis = "steps") -> list[Line]:
    """Every line of the curves figure: per (suite, label) group and split, the seeds'
    curves on a common grid, their mean and 95% CI. Held-out lines only for suites
    that have held-out morphologies."""
    if metric not in METRICS:
        raise VizError(f"metric={metric}: expected one of {', '.join(METRICS)}")
    lines = []
    for (suite, label), members in group_runs(runs).items():
        for split, _ in _SPLITS:
            if split == "train":
                curves = [_training_curve(run, metric, x) for run in members]
            else:
                curves = [c for c in (curve(run, metric, split, x) for run in members) if c]
            if curves:
                grid, values = on_grid(curves)
                stats = mean_ci(values)
                lines.append(Line(suite, split, label, grid, *stats, len(curves), tuple(curves)))
    return lines


def robot_lines(runs: Sequence[Run], metric: Metric = "eval", x: Axis = "steps") -> list[Line]:
    """A line per (suite, label) group and robot of the suite (``Line.split``: the
    robot), from each run's ``<metric>/<robot>/return``: the paper's figures, one panel
    per robot."""
    if metric not in METRICS:
        raise VizError(f"metric={metric}: expected one of {', '.join(METRICS)}")
    lines = []
    for (suite, label), members in group_runs(runs).items():
        for robot in members[0].names:
            key = f"{metric}/{robot}/return"
            curves = [c for c in (_series(run, metric, key, x) for run in members) if c]
            if curves:
                grid, values = on_grid(curves)
                lines.append(
                    Line(suite, robot, label, grid, *mean_ci(values), len(curves), tuple(curves))
                )
    return lines


def plot_robot_curves(
    runs: Sequence[Run], out_dir: str | Path, metric: Metric = "eval", x: Axis = "steps"
) -> list[Path]:
    """A panel per robot of each suite (a row per suite), one line per (method, varying
    config) as ``plot_curves``; writes ``curves-<metric>[-wall]-robots.png`` and ``.svg``
    (nothing for runs of one robot each)."""
    if x not in AXES:
        raise VizError(f"x={x}: expected one of {', '.join(AXES)}")
    lines = robot_lines(runs, metric, x)
    suites = list(dict.fromkeys(line.suite for line in lines))
    robots = {s: list(dict.fromkeys(li.split for li in lines if li.suite == s)) for s in suites}
    if max((len(names) for names in robots.values()), default=0) < 2:
        return []
    held_out = {name for run in runs for name in run.held_out}
    labels = list(dict.fromkeys(line.label for line in lines))
    columns = max(len(names) for names in robots.values())
    fig, axes = new_figure(len(suites), columns, (4.0, 3.0))
    for line in lines:
        ax = axes[suites.index(line.suite), robots[line.suite].index(line.split)]
        draw_line(ax, line, colour(labels.index(line.label), len(labels)))
    for suite, row in zip(suites, axes, strict=True):
        for ax in row[len(robots[suite]) :]:
            ax.axis("off")
        for robot, ax in zip(robots[suite], row, strict=False):
            title = f"{robot}" + (" (held out)" if robot in held_out else "")
            ax.set(title=title, xlabel=AXES[x], ylabel="return")
            ax.grid(alpha=0.3)
        row[0].legend(fontsize="small")
    fig.suptitle(f"{METRICS[metric][1]}, per robot\nmean and 95% CI over n seeds")
    name = f"curves-{metric}" + ("-wall" if x == "wall" else "") + "-robots"
    return save(fig, out_dir, name)


def draw_line(ax, line: Line, line_colour) -> None:
    """``line`` on ``ax``: its mean and 95% band, or each seed as logged below
    ``BAND_SEEDS`` seeds; one legend entry either way."""
    label = f"{line.label} (n={line.seeds})"
    if line.seeds < BAND_SEEDS:
        for i, (steps, values) in enumerate(line.runs):
            ax.plot(steps, values, color=line_colour, lw=1.2, label=None if i else label)
        return
    ax.plot(line.steps, line.mean, color=line_colour, label=label)
    ax.fill_between(line.steps, line.low, line.high, color=line_colour, alpha=0.2, lw=0)


def plot_curves(
    runs: Sequence[Run], out_dir: str | Path, metric: Metric = "eval", x: Axis = "steps"
) -> list[Path]:
    """One row per suite, the training panel and (for suites with held-out morphologies)
    the zero-shot panel; one line per (method, varying config) with its 95% CI over
    seeds, or its seeds one by one when fewer than ``BAND_SEEDS``; against env steps or
    wall seconds (``x``). Writes ``curves-<metric>.png`` and ``.svg`` under ``out_dir``
    (``curves-<metric>-wall`` against wall seconds)."""
    if x not in AXES:
        raise VizError(f"x={x}: expected one of {', '.join(AXES)}")
    lines = curve_lines(runs, metric, x)
    suites = list(dict.fromkeys(line.suite for line in lines))
    labels = list(dict.fromkeys(line.label for line in lines))
    splits = [split for split, _ in _SPLITS if any(line.split == split for line in lines)]
    fig, axes = new_figure(len(suites), len(splits), (6.0, 4.0))
    for line in lines:
        ax = axes[suites.index(line.suite), splits.index(line.split)]
        line_colour = colour(labels.index(line.label), len(labels))
        draw_line(ax, line, line_colour)
    titles = dict(_SPLITS)
    for suite, row in zip(suites, axes, strict=True):
        for split, ax in zip(splits, row, strict=True):
            if not ax.lines:  # a suite without held-out morphologies
                ax.axis("off")
                continue
            ax.set(title=f"{suite_name(suite)}: {titles[split]}", xlabel=AXES[x], ylabel="return")
            ax.grid(alpha=0.3)
            ax.legend(fontsize="small")
    fig.suptitle(
        f"{METRICS[metric][1]}\nmean and 95% CI over n seeds; each seed where n < {BAND_SEEDS}"
    )
    return save(fig, out_dir, f"curves-{metric}" + ("-wall" if x == "wall" else ""))

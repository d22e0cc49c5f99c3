"""The end of a run: its summary table and its figures, read from the run directory.

Everything comes from ``config.json`` and ``metrics.jsonl`` (``runs.Run``), so a
summary printed at the end of ``train`` or ``sweep`` equals what the metrics file says,
and ``summary(load_run(dir))`` reprints it for any finished run.

- Per morphology: the final deterministic return (the last evaluation), the best one
  after training started and the step it came at (a short noisy run may end below its
  best), the noisy
  return (mean of the last ``NOISY_ROUNDS`` rounds' first episodes, with exploration
  noise: what the reference logs), the deterministic return normalised by the expert
  return of algorithm.md §6 (100% = the expert, 0% = a return of 0), and the number of
  synergies of the last round.
- Wall time from the rounds' ``perf/*`` fields: compilation, collection (evaluations
  apart), updates, and the fixed cost of a round (re-clustering, diagnostics, dispatch),
  the intercept of a least-squares line of each round's update time against its
  iterations: re-clustering runs inside the round's jitted program, interleaved with the
  updates, so it is measured by its cost per round rather than by a clock of its own.
"""

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from solar_jax.viz.runs import Run, suite_name

EXPERT_RETURNS = {
    "walker_2_main": 3492.0,
    "walker_3_main": 3747.6,
    "walker_4_main": 4839.0,
    "walker_5_main": 7280.0,
    "walker_6_main": 5544.0,
    "walker_7_main": 5560.5,
    "hopper_3": 4023.3,
    "hopper_4": 4687.1,
    "hopper_5": 5186.0,
    "humanoid_2d_7_left_arm": 7068.9,
    "humanoid_2d_7_left_leg": 3668.6,
    "humanoid_2d_7_lower_arms": 7285.2,
    "humanoid_2d_7_right_arm": 7106.1,
    "humanoid_2d_7_right_leg": 3584.8,
    "humanoid_2d_8_left_knee": 4521.4,
    "humanoid_2d_8_right_knee": 4698.8,
    "humanoid_2d_9_full": 7241.8,
    "cheetah_2_back": 1051.4,
    "cheetah_2_front": 2906.0,
    "cheetah_3_back": 2384.7,
    "cheetah_3_balanced": 2126.0,
    "cheetah_3_front": 3861.3,
    "cheetah_4_allback": 3364.4,
    "cheetah_4_allfront": 4528.7,
    "cheetah_4_back": 4360.6,
    "cheetah_4_front": 4375.0,
    "cheetah_5_back": 5737.0,
    "cheetah_5_balanced": 6539.4,
    "cheetah_5_front": 4052.5,
    "cheetah_6_back": 7047.5,
    "cheetah_6_front": 5489.4,
    "cheetah_7_full": 6716.0,
}
"""Per-robot expert returns at 1000 steps (algorithm.md §6: the ``modular_rl`` part of a
D4RL fork), the 100% mark of the normalised score; a ceiling, not a baseline."""

NOISY_ROUNDS = 10


@dataclasses.dataclass(frozen=True)
class MorphologyRow:
    name: str
    held_out: bool
    initial: float
    """Deterministic return before training (the evaluation at round 0)."""
    final: float
    """Deterministic return of the last evaluation."""
    best: float
    """The best deterministic return of an evaluation after training started (round > 0)."""
    best_step: int | None
    """The counted env steps of that evaluation."""
    noisy: float
    """Mean first-episode return of the last ``NOISY_ROUNDS`` rounds, with exploration noise."""
    normalised: float | None
    """``final`` / the expert return (algorithm.md §6), None for robots without one."""
    synergies: int | None
    """Synergies of the last round; None for methods without."""


@dataclasses.dataclass(frozen=True)
class Timing:
    compile_s: float
    collect_s: float
    """Training rounds' collection."""
    eval_s: float
    """Deterministic evaluations."""
    update_s: float
    """Training rounds' jitted update programs (re-clustering included)."""
    round_cost_s: float | None
    """Fixed cost of one round's update program (re-clustering, diagnostics, dispatch):
    the intercept of update time against iterations; None with fewer than 3 rounds of
    distinct iteration counts."""
    rounds: int


@dataclasses.dataclass(frozen=True)
class Summary:
    path: Path
    suite: str
    method: str
    env_steps: int
    updates: int
    rows: tuple[MorphologyRow, ...]
    timing: Timing
    evals: tuple[dict, ...] = ()
    """The evaluation records (the mean rows' best evaluation)."""
    schedule: str = "paper"


def _last(records: list[dict], key: str):
    return next((r[key] for r in reversed(records) if key in r), None)


def best_evaluation(evals: list[dict], names) -> tuple[float, int | None]:
    """(the best mean return over ``names`` of an evaluation after round 0, its env
    steps); (nan, None) before the first."""
    scored = [
        (float(np.mean([r[f"eval/{n}/return"] for n in names])), int(r["env_steps"]))
        for r in evals
        if r["round"] > 0 and all(f"eval/{n}/return" in r for n in names)
    ]
    return max(scored, key=lambda x: x[0]) if scored else (float("nan"), None)


def summary(run: Run) -> Summary:
    """The summary of a run directory's records (``runs.load_run``)."""
    rounds, evals = run.records_of("round"), run.records_of("eval")
    first = next((r for r in evals if r["round"] == 0), None)
    rows = []
    for name in run.names:
        expert = EXPERT_RETURNS.get(name)
        final = _last(evals, f"eval/{name}/return")
        noisy = [r[f"episode/{name}/return"] for r in rounds[-NOISY_ROUNDS:]]
        synergies = _last(rounds, f"synergy/{name}/num_clusters")
        best, best_step = best_evaluation(evals, [name])
        rows.append(
            MorphologyRow(
                name=name,
                held_out=name in run.held_out,
                initial=float("nan") if first is None else first[f"eval/{name}/return"],
                final=float("nan") if final is None else final,
                best=best,
                best_step=best_step,
                noisy=float(np.mean(noisy)) if noisy else float("nan"),
                normalised=None if expert is None or final is None else final / expert,
                synergies=synergies,
            )
        )
    last = run.records[-1]
    return Summary(
        path=run.path,
        suite=run.suite,
        method=run.method,
        env_steps=int(last["env_steps"]),
        updates=int(last["updates"]),
        rows=tuple(rows),
        timing=timing(rounds, evals),
        evals=tuple(evals),
        schedule=str(run.config.get("schedule", "paper")),  # runs from before the switch
    )


def timing(rounds: list[dict], evals: list[dict]) -> Timing:
    """Wall time of a run from its rounds' and evaluations' ``perf/*`` fields."""

    def total(records, key):
        return float(sum(r.get(key, 0.0) for r in records))

    update_s = np.array([r.get("perf/train_s", np.nan) for r in rounds])
    updates = np.array([r["updates"] for r in rounds], dtype=np.float64)
    iterations = np.diff(updates, prepend=0.0)
    known = np.isfinite(update_s)
    round_cost = None
    if len(np.unique(iterations[known])) >= 3:
        _, intercept = np.polyfit(iterations[known], update_s[known], 1)
        round_cost = float(max(intercept, 0.0))
    return Timing(
        compile_s=total(rounds, "perf/compile_s") + total(evals, "perf/compile_s"),
        collect_s=total(rounds, "perf/collect_s"),
        eval_s=total(evals, "perf/eval_s"),
        update_s=float(np.nansum(update_s)),
        round_cost_s=round_cost,
        rounds=len(rounds),
    )


def _number(value: float | None, fmt: str = ",.1f") -> str:
    return "-" if value is None or not np.isfinite(value) else format(value, fmt)


def _best(value: float, step: int | None) -> str:
    return "-" if step is None else f"{_number(value)} @ {step:,}"


def format_summary(s: Summary, figures: list[Path] = ()) -> str:
    """The summary as a plain-text table and a few lines."""
    header = ("morphology", "split", "start", "final", "best (at step)", "noisy", "expert %")
    header += ("synergies",)
    body = [
        (
            row.name,
            "held out" if row.held_out else "train",
            _number(row.initial),
            _number(row.final),
            _best(row.best, row.best_step),
            _number(row.noisy),
            _number(None if row.normalised is None else 100 * row.normalised, ".1f"),
            "-" if row.synergies is None else str(row.synergies),
        )
        for row in s.rows
    ]
    splits = {"train": [r for r in s.rows if not r.held_out], "held out": []}
    splits["held out"] = [r for r in s.rows if r.held_out]
    for split, rows in splits.items():
        if len(s.rows) == 1 or not rows:
            continue
        scores = [r.normalised for r in rows if r.normalised is not None]
        body.append(
            (
                f"mean ({split})",
                "",
                _number(np.mean([r.initial for r in rows])),
                _number(np.mean([r.final for r in rows])),
                _best(*best_evaluation(list(s.evals), [r.name for r in rows])),
                _number(np.mean([r.noisy for r in rows])),
                _number(100 * np.mean(scores) if scores else None, ".1f"),
                "",
            )
        )
    widths = [max(len(str(line[i])) for line in [header, *body]) for i in range(len(header))]

    def line(cells):
        return "  ".join(
            str(c).ljust(w) if i < 2 else str(c).rjust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    t = s.timing
    wall = t.compile_s + t.collect_s + t.eval_s + t.update_s
    per_round = (
        "-"
        if t.round_cost_s is None
        else f"{t.round_cost_s:.2f} s/round x {t.rounds} rounds = {t.round_cost_s * t.rounds:.0f} s"
    )
    lines = [
        f"{suite_name(s.suite)}, {s.method}, {s.schedule} schedule: {s.env_steps:,} env steps, "
        f"{s.updates:,} updates",
        line(header),
        *(line(cells) for cells in body),
        "start/final/best: deterministic return before training / at the last evaluation / "
        "at the best evaluation since (its counted env steps); noisy: "
        f"last {NOISY_ROUNDS} rounds' episodes with exploration noise; expert %: final / the "
        "expert return of docs/algorithm.md §6",
        f"wall {wall:,.0f} s: compile {t.compile_s:,.0f}, collection {t.collect_s:,.0f}, "
        f"evaluation {t.eval_s:,.0f}, updates {t.update_s:,.0f} (of which the fixed cost "
        f"of a round, re-clustering included: {per_round})",
        f"run directory: {s.path}",
    ]
    lines += [f"figure: {path}" for path in figures if Path(path).suffix == ".png"]
    return "\n".join(lines)


def write_figures(run: Run, out_dir: str | Path | None = None) -> list[Path]:
    """The run's learning curves (deterministic and noisy; per robot too, for a suite),
    and for SOLAR its latest synergies and the number of synergies over training, under
    ``out_dir`` (default ``RUN_DIR/plots``), overwritten on each call. Returns the paths
    written."""
    from solar_jax.viz.curves import plot_curves, plot_robot_curves

    out_dir = Path(out_dir or run.path / "plots")
    paths = plot_curves([run], out_dir, "eval") + plot_robot_curves([run], out_dir, "eval")
    if run.records_of("round"):  # from the first round on
        paths += plot_curves([run], out_dir, "episode")
    if run.has_synergies:
        from solar_jax.viz.synergy import draw_synergies, plot_clusters

        paths += draw_synergies(run, out_dir, stem="synergy-latest")
        paths += plot_clusters([run], out_dir)
    return paths


REDRAW_EVERY_S = 60.0
"""During a run, its figures are redrawn at an evaluation at most this often, and always
at its end (the commands). A redraw writes every figure as PNG and SVG, 0.7-0.8 s for the
quickstart on a 2-core CPU: at every evaluation that is 5% of its run."""


class Redraw:
    """A run's live figures: ``redraw(run_dirs)`` after an evaluation calls
    ``draw(run_dirs)`` when ``every_s`` seconds have passed since the last draw (or since
    it was made), else remembers ``run_dirs`` for the next draw. Returns what ``draw``
    wrote (nothing when it waits)."""

    def __init__(
        self,
        draw: Callable[[list[Path]], list[Path]],
        every_s: float = REDRAW_EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.draw, self.every_s, self.clock = draw, every_s, clock
        self.last = clock()
        self.pending: dict[Path, None] = {}  # ordered: run directories not drawn since

    def __call__(self, run_dirs: list[Path]) -> list[Path]:
        self.pending.update(dict.fromkeys(run_dirs))
        if self.clock() - self.last < self.every_s:
            return []
        paths = self.draw(list(self.pending))
        self.pending.clear()
        self.last = self.clock()
        return paths

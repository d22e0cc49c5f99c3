"""``python -m solar_jax.evaluate RUN_DIR... [variants=dynamics,kinematics] [per_property=4]``

Zero-shot to new dynamics and kinematics (the SOLAR paper's appendix table): each run's
trained deterministic policy on variants of its training robots
(``morphology.variants``: the paper's ranges, or ``variants=armature=0.1:1,...``), one
property at a time, ``per_property`` variants per property and robot, drawn from
``seed``; beside them the nominal robots. All variants of a suite run as one batch in
one compiled program (``env.variants``), one episode each.

Per run: the first episode's return of every robot and variant. The table has a row per
property: the mean return over robots and variants, its 95% interval over the runs of a
method (seeds; one run: over its robots and variants), and its ratio to the nominal
robots' mean. RUN_DIRs are run or sweep directories; runs group by method (and by any
config key that differs, as ``plot`` groups them). Writes ``zeroshot.json``,
``zeroshot.md`` and ``zeroshot.png``/``.svg`` to ``out=`` (default
``RUN_DIR/zeroshot`` for one run, else ``./zeroshot``), and each run's own returns to
``RUN_DIR/zeroshot/returns.json``.
"""

import dataclasses
import json
import re
import sys
import typing
from pathlib import Path

from solar_jax.cli import help_text, parse_overrides, wants_help
from solar_jax.config import ConfigError
from solar_jax.morphology.variants import Variation, VariationError
from solar_jax.training.checkpoint import CheckpointError
from solar_jax.training.rundir import checkpoint_steps
from solar_jax.training.zeroshot import evaluate_run, summarise
from solar_jax.viz.runs import VizError, group_runs, load_runs, run_dirs
from solar_jax.viz.zeroshot import figure, markdown
from solar_jax.xla.cache import enable_compilation_cache


@dataclasses.dataclass(frozen=True)
class EvaluateOptions:
    """The ``key=value`` options of ``python -m solar_jax.evaluate``."""

    variants: str = "dynamics,kinematics"
    """Properties to vary, one at a time: dynamics (armature, density, damping, gear),
    kinematics (limb_radius, limb_height, joint_range), or names, each optionally with
    its range (``limb_height=0.2:0.4``, ``joint_range=-45:45/0:60``)."""

    per_property: int = 4
    """Variants per property and robot (the paper: 4)."""

    seed: int = 0
    """Seed of the variants' draws and of the episodes' reset noise."""

    checkpoint: typing.Literal["latest", "best"] = "latest"
    """Each run's latest checkpoint, or its best evaluation's policy."""

    robots: typing.Literal["train", "all"] = "train"
    """The suite's training robots, or its held-out ones too."""

    out: str = ""
    """Output folder (default RUN_DIR/zeroshot for one run, else ./zeroshot)."""

    reuse: bool = False
    """Take a run's returns from its ``zeroshot/returns.json`` where that was written with
    the same variants, per_property, seed, checkpoint and robots and the run's
    checkpoints have not changed since (to tabulate runs evaluated separately)."""

    def __post_init__(self):
        if self.per_property < 1:
            raise ValueError(f"per_property must be >= 1, got {self.per_property}")
        Variation.parse(self.variants)  # a bad variation is an error before anything runs


_OPTION = re.compile(r"^[A-Za-z_][\w.]*=")


def parse(argv: list[str]) -> tuple[list[str], EvaluateOptions]:
    """(run directories, options) of a command line."""
    options = parse_overrides(EvaluateOptions(), [a for a in argv if _OPTION.match(a)])
    return [a for a in argv if not _OPTION.match(a)], options


def _evaluated_with(options: EvaluateOptions) -> dict:
    """The options that decide a run's returns."""
    keys = ("variants", "per_property", "seed", "checkpoint", "robots")
    return {key: getattr(options, key) for key in keys}


def _reusable(path: Path, stamp: dict) -> bool:
    """Whether the returns in ``path`` were evaluated as ``stamp`` says (unreadable: no)."""
    try:
        return json.loads(path.read_text()).get("evaluated_with") == stamp
    except (OSError, ValueError, AttributeError):
        return False


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    asked, section = wants_help(argv)
    if asked:
        print(help_text(EvaluateOptions(), __doc__, section))
        return 0
    try:
        paths, options = parse(argv)
        runs = load_runs(paths)
        dirs = run_dirs(paths)
    except (ConfigError, VariationError, VizError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    enable_compilation_cache()
    programs, results = {}, []
    try:
        for run_dir in dirs:
            own = Path(run_dir) / "zeroshot" / "returns.json"
            stamp = {**_evaluated_with(options), "checkpoints": checkpoint_steps(run_dir)}
            if options.reuse and _reusable(own, stamp):
                results.append(json.loads(own.read_text()))
                print(f"{run_dir}: from {own}", flush=True)
                continue
            result = {**evaluate_run(run_dir, options, programs), "evaluated_with": stamp}
            own.parent.mkdir(parents=True, exist_ok=True)
            own.write_text(json.dumps(result, indent=1))
            print(f"{run_dir}: {result['seconds']:.0f} s", flush=True)
            results.append(result)
    except (CheckpointError, VariationError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    by_dir = {str(d): r for d, r in zip(dirs, results, strict=True)}
    groups = {
        label: [by_dir[str(run.path)] for run in members]
        for (_, label), members in group_runs(runs).items()
    }
    table = summarise(groups)
    out = Path(options.out or (Path(dirs[0]) / "zeroshot" if len(dirs) == 1 else "zeroshot"))
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(table)
    (out / "zeroshot.md").write_text(text + "\n")
    payload = {"options": dataclasses.asdict(options), "table": table, "runs": results}
    (out / "zeroshot.json").write_text(json.dumps(payload, indent=1))
    suites = ", ".join(dict.fromkeys(run.suite for run in runs))
    written = figure(table, out, f"zero-shot to variants: {suites}")
    print(text)
    for path in [out / "zeroshot.md", out / "zeroshot.json", *written]:
        print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``python -m solar_jax.plot [curves|synergy|clusters|video|summary|all] RUN_DIR... [key=value]``

Plots of finished or running runs (docs/outputs.md). RUN_DIRs are run
directories or sweep directories (expanded into their lanes), in any mix.

- ``curves``: learning curves, mean and 95% CI over seeds (``metric=eval|episode``),
  against env steps or wall seconds (``x=steps|wall``); for suites of several robots,
  also a panel per robot (``curves-<metric>-robots``).
- ``synergy``: each run's robots with their synergies (``round=``, default the last).
- ``clusters``: the number of synergies over training.
- ``all`` (the default): the three above; runs without synergies get curves only.
- ``summary``: each run's end-of-run table as ``train`` prints it, from its metrics (a
  run still going: so far).
- ``video``: one run's latest policy, or its best (``checkpoint=best``), on one robot
  (``morph=``, ``steps=``, ``width=``, ``height=``; ``out=FILE.gif|.mp4``), needs an
  OpenGL backend (``MUJOCO_GL``).

Figures go to ``out=DIR`` (default ``RUN_DIR/plots`` for one directory, else
``./plots``) as PNG and SVG; the paths written are printed.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # read by mujoco on import: before any import of it

import dataclasses  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import typing  # noqa: E402
from pathlib import Path  # noqa: E402

from solar_jax.cli import help_text, parse_overrides, wants_help  # noqa: E402
from solar_jax.config import ConfigError  # noqa: E402
from solar_jax.experiments import one_line_errors  # noqa: E402
from solar_jax.viz.curves import plot_curves, plot_robot_curves  # noqa: E402
from solar_jax.viz.gl import RenderError, import_mujoco  # noqa: E402
from solar_jax.viz.runs import VizError, load_runs  # noqa: E402


@dataclasses.dataclass(frozen=True)
class PlotOptions:
    """The ``key=value`` options of ``python -m solar_jax.plot``."""

    out: str = ""
    """Figures: a folder (default RUN_DIR/plots for one directory given, else ./plots).
    video: a .gif or .mp4 file (default RUN_DIR/plots/video-<morph>-round<r>.gif)."""

    metric: typing.Literal["eval", "episode"] = "eval"
    """curves: deterministic evaluations, or the noisy per-round episodes (the paper's)."""

    x: typing.Literal["steps", "wall"] = "steps"
    """curves: against counted env steps, or the runs' own wall seconds (compiles, rounds
    and evaluations summed; schedules compared at equal time)."""

    round: int | None = None
    """synergy: the round whose clustering to draw (default: each run's last)."""

    morph: str = ""
    """video: the robot (default: the suite's first)."""

    steps: int = 1000
    """video: env steps at most (the video stops at the first episode end)."""

    width: int = 480
    """video: frame width in pixels."""

    height: int = 360
    """video: frame height in pixels."""

    checkpoint: typing.Literal["latest", "best"] = "latest"
    """video: the policy of the latest checkpoint, or of the best evaluation
    (``checkpoints/best``)."""

    def __post_init__(self):
        for name in ("steps", "width", "height"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")


COMMANDS: dict[str, tuple[str, ...]] = {
    "all": ("out", "metric", "x", "round"),
    "curves": ("out", "metric", "x"),
    "synergy": ("out", "round"),
    "clusters": ("out",),
    "video": ("out", "morph", "steps", "width", "height", "checkpoint"),
    "summary": (),
}
"""Subcommand -> the options it takes."""

_OPTION = re.compile(r"^[A-Za-z_][\w.]*=")


def parse(argv: list[str]) -> tuple[str, list[str], PlotOptions]:
    """(subcommand, paths, options) of a command line."""
    command = argv[0] if argv and argv[0] in COMMANDS else "all"
    rest = argv[1:] if argv and argv[0] in COMMANDS else argv
    options = [arg for arg in rest if _OPTION.match(arg)]
    paths = [arg for arg in rest if not _OPTION.match(arg)]
    parsed = parse_overrides(PlotOptions(), options)
    for arg in options:
        key = arg.partition("=")[0]
        if key not in COMMANDS[command]:
            raise ConfigError(
                f"{command} does not take {key}=; it takes {', '.join(COMMANDS[command])}"
            )
    if not paths:
        raise VizError(f"no run directories given: python -m solar_jax.plot {command} RUN_DIR...")
    return command, paths, parsed


def _out_dir(paths: list[str], options: PlotOptions) -> Path:
    if options.out:
        return Path(options.out)
    return Path(paths[0]) / "plots" if len(paths) == 1 else Path("plots")


def run(command: str, paths: list[str], options: PlotOptions) -> list[Path]:
    """Makes the plots of ``command``; returns the paths written."""
    if command == "video":
        if len(paths) != 1:
            raise VizError(f"video takes one run directory, got {len(paths)}")
        import_mujoco()  # before JAX and the trainer: a missing backend fails fast
        from solar_jax.viz.video import rollout_video
        from solar_jax.xla.cache import enable_compilation_cache

        enable_compilation_cache()  # the rollout's MJX step: 20-30 s to compile on a CPU
        sizes = dict(steps=options.steps, width=options.width, height=options.height)
        which = dict(checkpoint=options.checkpoint)
        return [rollout_video(paths[0], options.out or None, options.morph, **sizes, **which)]
    runs = load_runs(paths)
    if command == "summary":
        from solar_jax.viz.report import format_summary, summary

        for r in runs:
            print(format_summary(summary(r)))
        return []
    out_dir = _out_dir(paths, options)
    written = []
    if command in ("all", "curves"):
        written += plot_curves(runs, out_dir, options.metric, options.x)
        written += plot_robot_curves(runs, out_dir, options.metric, options.x)
    if command == "curves":
        return written
    import_mujoco()  # the drawings build the robots in MuJoCo
    from solar_jax.viz.synergy import draw_all_synergies, plot_clusters

    if command == "all":  # a comparison with baselines: their curves, no error
        for skipped in (r for r in runs if not r.has_synergies):
            print(f"note: {skipped.path} ({skipped.method}) has no synergies", file=sys.stderr)
        runs = [r for r in runs if r.has_synergies]
        if not runs:
            return written
    if command in ("all", "synergy"):
        written += draw_all_synergies(runs, out_dir, options.round)
    if command in ("all", "clusters"):
        written += plot_clusters(runs, out_dir)
    return written


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv

    def plot(argv: list[str]) -> int:
        asked, section = wants_help(argv)
        if asked:
            print(help_text(PlotOptions(), __doc__, section))
            return 0
        for path in run(*parse(argv)):
            print(path)
        return 0

    return one_line_errors(plot, argv, user_errors=(VizError, RenderError))


if __name__ == "__main__":
    sys.exit(main())

"""Plots, synergy drawings, rollout videos and end-of-run summaries of run directories
(never imported by the training layers; the ``train`` and ``sweep`` commands call
``report`` at the end). ``python -m solar_jax.plot`` is the command line.

- ``runs``: run and sweep directories read and grouped into lines.
- ``stats``: the common step grid and Student-t confidence intervals.
- ``curves``: learning curves over seeds, training and held-out panels.
- ``synergy``: robots drawn with their synergies; the number of synergies over training.
- ``video``: the latest checkpoint's policy rolled out and rendered (GIF or MP4).
- ``gl``: MuJoCo's OpenGL backend, or one clear error.
- ``report``: a run's summary table and its figures (``train`` and ``sweep`` at the end).

``synergy`` and ``video`` import MuJoCo (and ``video`` JAX); this package's namespace
holds only what needs neither.
"""

from solar_jax.viz.curves import plot_curves
from solar_jax.viz.runs import Run, VizError, group_runs, load_runs, run_dirs
from solar_jax.viz.stats import mean_ci, on_grid

__all__ = [
    "Run",
    "VizError",
    "group_runs",
    "load_runs",
    "mean_ci",
    "on_grid",
    "plot_curves",
    "run_dirs",
]

"""Across-seed statistics of learning curves: a common step grid, and the Student-t
interval of ``solar_jax.stats`` (shared with the sweep's summary)."""

from collections.abc import Sequence

import numpy as np

from solar_jax.stats import mean_ci

__all__ = ["MAX_POINTS", "common_grid", "mean_ci", "on_grid"]

MAX_POINTS = 500
"""Grid points at most (per-round curves of a long run have thousands of rounds)."""


def common_grid(steps: Sequence[np.ndarray], max_points: int = MAX_POINTS) -> np.ndarray:
    """Evenly spaced env steps on which every curve of ``steps`` is defined.

    From the latest first point to the earliest last point (0 to the shortest run's
    final step for evaluation curves, which all start at 0), spaced like the logged
    points (the median gap), with at most ``max_points`` points.
    """
    start = max(float(s[0]) for s in steps)
    end = min(float(s[-1]) for s in steps)
    if end <= start:
        return np.array([end])
    gaps = np.concatenate([np.diff(np.asarray(s, dtype=np.float64)) for s in steps])
    gap = np.median(gaps[gaps > 0]) if np.any(gaps > 0) else end - start
    count = int(np.clip(np.floor((end - start) / gap) + 1, 2, max_points))
    return np.linspace(start, end, count)


def on_grid(
    curves: Sequence[tuple[np.ndarray, np.ndarray]], max_points: int = MAX_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """(grid ``[T]``, values ``[runs, T]``): each run's ``(steps, values)`` curve linearly
    interpolated onto ``common_grid`` (seeds log at different env steps, since a round
    ends with its episodes, so their points never line up exactly)."""
    grid = common_grid([steps for steps, _ in curves], max_points)
    return grid, np.stack([np.interp(grid, steps, values) for steps, values in curves])

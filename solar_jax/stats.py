"""Statistics over seeds (algorithm.md §6: mean and 95% confidence interval over seeds; the
interval of a difference between two sets of seeds)."""

import numpy as np
from scipy import stats


def mean_ci(values: np.ndarray, level: float = 0.95) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, low, high) over the seed axis of ``values`` ``[seeds, T]``.

    Student-t interval: mean ± t_{(1+level)/2, n-1} · s / √n with the sample standard
    deviation s (ddof 1); with one seed the interval is the mean itself.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[0] < 1:
        raise ValueError(f"expected values [seeds, T] with at least one seed, got {values.shape}")
    n = values.shape[0]
    mean = values.mean(axis=0)
    if n == 1:
        return mean, mean.copy(), mean.copy()
    half = stats.t.ppf((1 + level) / 2, n - 1) * values.std(axis=0, ddof=1) / np.sqrt(n)
    return mean, mean - half, mean + half


def welch_interval(a: np.ndarray, b: np.ndarray, level: float = 0.90) -> tuple[float, float]:
    """The ``level`` interval of mean(a) - mean(b) over seeds ``[n_a]``, ``[n_b]`` (at least
    two each), Welch-Satterthwaite degrees of freedom."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if len(a) < 2 or len(b) < 2:
        raise ValueError(f"expected at least two seeds on each side, got {len(a)} and {len(b)}")
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    diff = a.mean() - b.mean()
    if va + vb == 0:
        return float(diff), float(diff)
    df = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    half = stats.t.ppf((1 + level) / 2, df) * np.sqrt(va + vb)
    return float(diff - half), float(diff + half)

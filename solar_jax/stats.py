"""Statistics over seeds (algorithm.md §6: mean and 95% confidence interval over seeds)."""

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

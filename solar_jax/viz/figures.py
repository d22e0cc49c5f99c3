"""Figures on matplotlib's Agg canvas, without pyplot: no global figure registry, no
backend switch for whoever imported us (a notebook keeps its own), nothing to close."""

from pathlib import Path

import numpy as np
from matplotlib import colormaps, rc_context
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

FORMATS = ("png", "svg")


def new_figure(rows: int, cols: int, panel: tuple[float, float]) -> tuple[Figure, np.ndarray]:
    """A figure of ``rows x cols`` panels of ``panel`` inches each: (figure, axes
    ``[rows, cols]``)."""
    fig = Figure(figsize=(panel[0] * cols, panel[1] * rows), layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False)


def colour(index: int, count: int) -> tuple:
    """The ``index``-th of ``count`` distinct colours (tab10, or tab20 beyond ten)."""
    palette = colormaps["tab10" if count <= 10 else "tab20"]
    return palette(index % palette.N)


def save(fig: Figure, out_dir: str | Path, stem: str) -> list[Path]:
    """Writes ``out_dir/stem.png`` and ``.svg`` (its text as text, editable and
    searchable); returns their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.{fmt}" for fmt in FORMATS]
    with rc_context({"svg.fonttype": "none"}):
        for path in paths:
            fig.savefig(path, dpi=120)
    return paths

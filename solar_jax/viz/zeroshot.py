"""The zero-shot table (``training.zeroshot.summarise``) as Markdown and as a figure."""

from pathlib import Path

import numpy as np

from solar_jax.training.zeroshot import NOMINAL
from solar_jax.viz.figures import colour, new_figure, save


def markdown(table: dict[str, dict[str, dict]]) -> str:
    groups = list(table)
    labels = list(table[groups[0]])
    head = "| variants | " + " | ".join(f"{g}: mean [95% CI] | ratio" for g in groups) + " |"
    lines = [head, "|---|" + "---:|---:|" * len(groups)]
    for label in labels:
        cells = []
        for g in groups:
            row = table[g][label]
            cells.append(
                f"{row['mean']:,.0f} [{row['ci95'][0]:,.0f}, {row['ci95'][1]:,.0f}] | "
                f"{row['ratio']:.2f}"
            )
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def figure(table: dict[str, dict[str, dict]], out_dir: Path, title: str) -> list[Path]:
    """Bars per property (one per group) with their 95% intervals; the nominal robots'
    mean as each group's dashed line."""
    groups = list(table)
    labels = [label for label in table[groups[0]] if label != NOMINAL]
    fig, axes = new_figure(1, 1, (1.2 + 0.9 * len(labels), 3.6))
    ax = axes[0, 0]
    width = 0.8 / len(groups)
    for g, name in enumerate(groups):
        rows = [table[name][label] for label in labels]
        x = np.arange(len(labels)) + (g - (len(groups) - 1) / 2) * width
        means = np.array([r["mean"] for r in rows])
        errors = np.abs(np.array([r["ci95"] for r in rows]).T - means)
        ax.bar(x, means, width, yerr=errors, capsize=3, color=colour(g, len(groups)), label=name)
        ax.axhline(table[name][NOMINAL]["mean"], color=colour(g, len(groups)), ls="--", lw=1)
    ax.set_xticks(np.arange(len(labels)), labels, rotation=20)
    ax.set_ylabel("episode return (dashed: nominal robots)")
    ax.set_title(title)
    ax.legend(fontsize="small")
    return save(fig, out_dir, "zeroshot")

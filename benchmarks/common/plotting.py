"""Shared matplotlib set-up (Agg, no display), CSV writing and the colours of the methods."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLORS = {
    "welch16": "#1f77b4",
    "welch32": "#2ca02c",
    "welch64": "#17becf",
    "welch128": "#8c564b",
    "welch_multi": "#000000",
    "gauss32": "#9467bd",
    "paired16": "#ff9896",
    "paired32": "#d62728",
    "paired64": "#e377c2",
    "paired128": "#7b1f1f",
    "paired_multi": "#bcbd22",
    "rmse": "#7f7f7f",
    "tilediff16": "#ff7f0e",
}


def save(fig, path: Path) -> str:
    """Write `fig` as PNG and close it; return the file name."""
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path).name


def write_csv(path: Path, rows: list[dict]) -> str:
    """Write dict rows (the first row's keys are the header); return the file name."""
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(v) for k, v in row.items()})
    return Path(path).name


def _fmt(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else value


__all__ = ["COLORS", "plt", "save", "write_csv"]

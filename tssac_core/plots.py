"""Figures from training metrics: figure 7 (return and cost per epoch) and figure 8 (the multiplier)."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_metrics(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _series(rows: list[dict[str, str]], role: str, key: str) -> tuple[list[int], list[float]]:
    sel = [r for r in rows if r["role"] == role and r[key] not in ("", "nan")]
    return [int(r["epoch"]) for r in sel], [float(r[key]) for r in sel]


def plot_training(metrics: Path, out: Path, cost_limit: float) -> None:
    """Write fig7_return_cost.png and fig8_multiplier.png next to the metrics."""
    rows = read_metrics(metrics)
    if not rows:
        return
    roles = [r for r in ("decoy", "detect", "strike") if any(row["role"] == r for row in rows)]
    fig, axes = plt.subplots(2, len(roles), figsize=(4.5 * len(roles), 6), squeeze=False)
    for col, role in enumerate(roles):
        x, y = _series(rows, role, "return")
        axes[0][col].plot(x, y, marker=".")
        axes[0][col].set_title(f"{role}: episode return")
        x, y = _series(rows, role, "cost")
        axes[1][col].plot(x, y, marker=".", color="tab:red")
        axes[1][col].axhline(cost_limit, color="red", ls="--", label=f"cost threshold C = {cost_limit:g}")
        axes[1][col].set_title(f"{role}: episode cost")
        axes[1][col].set_xlabel("epoch")
        axes[1][col].legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "fig7_return_cost.png", dpi=90)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(roles), figsize=(4.5 * len(roles), 3.2), squeeze=False)
    for col, role in enumerate(roles):
        ax = axes[0][col]
        for key, label in (("beta", "beta"), ("beta_minus_xi", "beta - xi (effective)"), ("xi", "xi")):
            x, y = _series(rows, role, key)
            ax.plot(x, y, label=label)
        ax.set_title(f"{role}: cost multiplier (epoch means)")
        ax.set_xlabel("epoch")
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig8_multiplier.png", dpi=90)
    plt.close(fig)

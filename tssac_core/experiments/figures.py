"""The paper's figures 7-12 from a grid's runs and evaluations (PNG, matplotlib's Agg backend).

- fig7_training.png: return and cost per epoch of the detect and strike roles, the paper's five algorithms
  (tssac, sac_lag, sac, ppo, cpo), mean over seeds with the seeds' range as a band, with the cost threshold C;
- fig8_multiplier.png: the multiplier beta (band over seeds) and beta - xi per epoch, with damping (tssac) and
  without (sac_lag);
- fig9_mission.png: one evaluation mission's trajectories (the first layout, flown by a TSSAC team);
- fig10_test_boxplots.png: per-episode test return and cost of each role, per algorithm (seeds pooled);
- fig11_generalization.png: success rate and cost on the generalisation scenario, per algorithm;
- fig12_penalty.png: SAC with hazard penalties beside TSSAC: success rate and cost.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tssac_core.experiments.evaluations import PerEpisode  # noqa: E402
from tssac_core.experiments.learning_curves import Rows  # noqa: E402
from tssac_core.experiments.summary import AlgorithmSummary, OverSeeds, Summary  # noqa: E402
from tssac_core.reporting.plots import plot_mission  # noqa: E402
from tssac_core.sim.missions import MissionResults  # noqa: E402
from tssac_core.sim.scenario import ROLES, Scenario  # noqa: E402
from tssac_core.train.algorithms import algorithm  # noqa: E402

Curves = dict[str, list[Rows]]
"""Entry name -> the metrics.csv rows of each of its finished seeds."""

DPI = 90


def seed_curves(runs: list[Rows], role: str, key: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per epoch: (epochs, mean, min, max) of ``key`` over the seeds that have a finite value there."""
    by_epoch: dict[int, list[float]] = {}
    for rows in runs:
        for r in rows:
            if r["role"] != role:
                continue
            try:
                value = float(r[key])
            except (KeyError, ValueError):
                continue
            if math.isfinite(value):
                by_epoch.setdefault(int(r["epoch"]), []).append(value)
    epochs = sorted(by_epoch)
    values = [np.asarray(by_epoch[e]) for e in epochs]
    return (
        np.asarray(epochs),
        np.asarray([v.mean() for v in values]),
        np.asarray([v.min() for v in values]),
        np.asarray([v.max() for v in values]),
    )


def mean_curve(runs: list[Rows], role: str, key: str) -> tuple[list[int], list[float]]:
    """Per epoch, the mean of ``key`` over the runs that have a finite value there."""
    epochs, mean, _, _ = seed_curves(runs, role, key)
    return [int(e) for e in epochs], [float(m) for m in mean]


def band(ax: Any, runs: list[Rows], role: str, key: str, colour: str, label: str, ls: str = "-") -> None:
    """The mean over seeds as a line, the seeds' range (min to max) as a shaded band."""
    x, mean, low, high = seed_curves(runs, role, key)
    if not len(x):
        return
    ax.plot(x, mean, color=colour, ls=ls, lw=1.4, label=label)
    if len(runs) > 1:
        ax.fill_between(x, low, high, color=colour, alpha=0.15, lw=0)


def seeds_label(name: str, runs: list[Rows]) -> str:
    return f"{name} ({len(runs)} seed{'' if len(runs) == 1 else 's'})"


def fig7_training(path: Path, curves: Curves, cost_limit: float) -> None:
    """Figure 7: return and cost per epoch of the detect and strike roles, one colour per algorithm: the mean
    over seeds, and the seeds' range as a band. ``curves``: the paper's five algorithms (penalties: figure 12)."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), squeeze=False, sharex=True)
    panels = iter("ABCD")
    for col, role in enumerate(("detect", "strike")):
        for i, (name, runs) in enumerate(curves.items()):
            for row, key in enumerate(("return", "cost")):
                band(axes[row][col], runs, role, key, f"C{i}", seeds_label(name, runs))
        for row, what in enumerate(("task performance: average epoch return", "safety: average epoch cost")):
            axes[row][col].set_title(f"({next(panels)}) {role} UAV, {what}", fontsize=10)
            axes[row][col].set_ylabel("return" if row == 0 else "hazard cost per episode")
            axes[row][col].grid(alpha=0.3)
        axes[1][col].axhline(cost_limit, color="red", ls="--", lw=1, label=f"cost threshold C = {cost_limit:g}")
        axes[1][col].set_yscale("symlog", linthresh=10)  # early epochs cost hundreds, the limit is 3
        axes[1][col].set_ylim(bottom=0)
        axes[1][col].set_xlabel("epoch")
    handles, labels = axes[1][1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 6), fontsize=8, frameon=False)
    fig.suptitle("Training of the five algorithms (line: mean over seeds; band: the seeds' range)", fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def fig8_multiplier(path: Path, curves: Curves) -> None:
    """Figure 8: the cost multiplier beta per epoch (solid) and the effective beta - xi (dotted), with damping
    (tssac) and without (sac_lag); mean over seeds, the band the seeds' range of beta. ``curves`` maps a label
    (e.g. "tssac (damped)") to its runs."""
    fig, axes = plt.subplots(1, len(ROLES), figsize=(4.6 * len(ROLES), 3.8), squeeze=False, sharey=True)
    for col, role in enumerate(ROLES):
        ax = axes[0][col]
        for i, (label, runs) in enumerate(curves.items()):
            band(ax, runs, role.value, "beta", f"C{i}", f"{seeds_label(label, runs)}: beta")
            x, y = mean_curve(runs, role.value, "beta_minus_xi")
            ax.plot(x, y, color=f"C{i}", ls=":", lw=1.2, label=f"{label}: beta - xi")
        ax.set_title(f"({'ABC'[col]}) {role.value} UAV", fontsize=10)
        ax.set_xlabel("epoch")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("cost multiplier")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, frameon=False)
    fig.suptitle(
        "Cost multiplier beta with and without damping (line: mean over seeds; band: the seeds' range)", fontsize=11
    )
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def fig9_mission(path: Path, results: MissionResults, scenario: Scenario, title: str) -> None:
    """Trajectories of the first recorded mission, drawn by tssac_core.reporting.plots.plot_mission."""
    assert results.trajectories is not None, "fly the mission with record=True"
    tracks: dict[str, list[tuple[float, float]]] = {}
    for j, role in enumerate(ROLES):
        xy = results.trajectories[0, :, j] / 1000.0
        xy = xy[np.isfinite(xy).all(axis=1)]
        tracks[role.value] = [(float(x), float(y)) for x, y in xy]
    r = scenario.ranges
    cost = ", ".join(f"{role.value} {results.cost[0, j]:g}" for j, role in enumerate(ROLES))
    verdict = "success" if results.success[0] else "failure"
    plot_mission(
        path,
        results.layouts[0],
        tracks,
        (r.strike_launch_km, r.detect_km, r.sam_launch_km, r.sam_detect_km),
        title=f"{title}\n{verdict}, {results.time_s[0]:.0f} s; hazard cost {cost}",
        area_km=scenario.area_km,
    )


def per_role(e: PerEpisode, key: str) -> np.ndarray:
    """An evaluation's per-mission ``return`` or ``cost``, (M, 3)."""
    values = e.returns if key == "return" else e.cost
    assert values is not None, "the 50-layout evaluations record the returns"
    return values.reshape(-1, len(ROLES))


def fig10_boxplots(path: Path, per_episode: dict[str, list[PerEpisode]], cost_limit: float) -> None:
    """``per_episode`` maps an entry name to the per-mission figures of its seeds' evaluations."""
    names = list(per_episode)
    fig, axes = plt.subplots(2, len(ROLES), figsize=(5 * len(ROLES), 7), squeeze=False)
    for col, role in enumerate(ROLES):
        for row, key in enumerate(("return", "cost")):
            data = [np.concatenate([per_role(e, key)[:, col] for e in per_episode[n]]) for n in names]
            ax = axes[row][col]
            ax.boxplot(data, tick_labels=names)
            ax.tick_params(axis="x", labelrotation=45, labelsize=7)
            ax.set_title(f"{role.value} UAV: test episode {key}")
        axes[1][col].axhline(cost_limit, color="red", ls="--", label=f"C = {cost_limit:g}")
        axes[1][col].set_yscale("symlog", linthresh=10)
        axes[1][col].set_ylim(bottom=0)
        axes[1][col].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def clipped_error(mean: Sequence[float], std: Sequence[float], low: float, high: float = math.inf) -> np.ndarray:
    """Error bars of ± std, cut where the quantity cannot go (a rate under 0 or over 100%, a cost under 0):
    shape (2, N), the lengths below and above each mean, as matplotlib's ``yerr`` takes them."""
    m, d = np.asarray(mean, dtype=float), np.asarray(std, dtype=float)
    return np.stack([np.minimum(d, np.maximum(m - low, 0.0)), np.minimum(d, np.maximum(high - m, 0.0))])


def bar_panel(
    path: Path,
    title: str,
    names: Sequence[str],
    rates: Sequence[OverSeeds],
    costs: Sequence[OverSeeds],
    cost_limit: float,
    reference: tuple[str, float, float] | None = None,
) -> None:
    """Success rate and cost bars (mean ± std over seeds) per entry; ``reference`` = (label, success, cost)."""
    labels = list(names)
    rate_mean = [100 * (s.mean if s.mean is not None else math.nan) for s in rates]
    rate_std = [100 * (s.std or 0.0) for s in rates]
    cost_mean = [c.mean if c.mean is not None else math.nan for c in costs]
    cost_std = [c.std or 0.0 for c in costs]
    if reference is not None:
        labels.append(reference[0])
        rate_mean.append(100 * reference[1])
        rate_std.append(0.0)
        cost_mean.append(reference[2])
        cost_std.append(0.0)
    x = np.arange(len(labels))
    rate_colours = ["tab:blue"] * len(names) + ["tab:gray"] * (reference is not None)
    cost_colours = ["tab:red"] * len(names) + ["tab:gray"] * (reference is not None)
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.1 * len(labels) * 2), 3.8))
    axes[0].bar(x, rate_mean, yerr=clipped_error(rate_mean, rate_std, 0.0, 100.0), capsize=3, color=rate_colours)
    axes[0].set_ylabel("success rate (%)")
    axes[0].set_ylim(0, 105)
    axes[1].bar(x, cost_mean, yerr=clipped_error(cost_mean, cost_std, 0.0), capsize=3, color=cost_colours)
    axes[1].axhline(cost_limit, color="red", ls="--", label=f"C = {cost_limit:g}")
    axes[1].set_ylabel("hazard cost per UAV per mission")
    axes[1].legend(fontsize=7)
    for ax in axes:
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


FIGURES = (
    "fig7_training.png",
    "fig8_multiplier.png",
    "fig9_mission.png",
    "fig10_test_boxplots.png",
    "fig11_generalization.png",
    "fig12_penalty.png",
)


def plot_figures(
    results: Path,
    summary: Summary,
    curves: Curves,
    per_episode: dict[str, list[PerEpisode]],
    mission: tuple[MissionResults, Scenario, str] | None,
) -> list[Path]:
    """Write every figure the data allows under ``results`` and delete those it no longer allows (a figure
    of runs that have since been moved away); returns the paths written."""
    written: list[Path] = []
    cost_limit = float(summary.cost_limit)
    done = [a for a in summary.algorithms.values() if a.seeds]
    paper = {a.name: curves[a.name] for a in done if a.name in curves and algorithm(a.algo).in_figure7}
    if paper:
        written.append(results / "fig7_training.png")
        fig7_training(written[-1], paper, cost_limit)
    damping = {
        f"{a.name} ({'damped' if a.algo == 'tssac' else 'no damping'})": curves[a.name]
        for a in done
        if a.algo in ("tssac", "sac_lag") and a.name in curves
    }
    if damping:
        written.append(results / "fig8_multiplier.png")
        fig8_multiplier(written[-1], damping)
    if mission is not None:
        written.append(results / "fig9_mission.png")
        fig9_mission(written[-1], *mission)
    if per_episode:
        written.append(results / "fig10_test_boxplots.png")
        fig10_boxplots(written[-1], per_episode, cost_limit)
    g = summary.guidance.generalization
    scenario = summary.evaluation.generalization_scenario
    generalization = [a.generalization for a in done if a.generalization is not None]
    if done and g is not None and scenario is not None and len(generalization) == len(done):
        written.append(results / "fig11_generalization.png")
        bar_panel(
            written[-1],
            f"Generalisation: {Path(scenario).name}",
            [a.name for a in done],
            [r.success_rate for r in generalization],
            [r.mean_cost for r in generalization],
            cost_limit,
            ("guidance", g.success_rate, g.mean_cost),
        )
    penalty = penalty_entries(done)
    if any(a.algo == "sac_penalty" for a in penalty):
        written.append(results / "fig12_penalty.png")
        bar_panel(
            written[-1],
            "SAC with a hazard penalty vs TSSAC",
            [a.name if a.algo == "tssac" else f"{a.name} (penalty {a.penalty:g})" for a in penalty],
            [a.random.success_rate for a in penalty],
            [a.random.mean_cost for a in penalty],
            cost_limit,
        )
    for name in FIGURES:
        if results / name not in written:
            (results / name).unlink(missing_ok=True)
    return written


def penalty_entries(done: Sequence[AlgorithmSummary]) -> list[AlgorithmSummary]:
    """Figure 12's bars: SAC with penalties 0, -10, -15, -50 ... then TSSAC. Penalty 0 is plain SAC (the same
    learner, the same run), so the ``sac`` entry stands for it unless the grid trains a penalty-0 entry too."""
    sac = [a for a in done if a.algo == "sac_penalty"]
    if not any(a.penalty == 0 for a in sac):
        sac += [dataclasses.replace(a, penalty=0.0) for a in done if a.algo == "sac"]
    return sorted(sac, key=lambda a: -a.penalty) + [a for a in done if a.algo == "tssac"]

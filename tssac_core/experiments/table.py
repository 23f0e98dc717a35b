"""``table4.md``: Table 4 beside the paper's, the tail and monitor columns, the mean cost against the limit, the
generalisation figures and the transfer speed-up, written from a :class:`~tssac_core.experiments.summary.Summary`;
and :func:`write_report`, which writes it with ``experiments.json``."""

from __future__ import annotations

from pathlib import Path

from tssac_core.common.cli import write_json
from tssac_core.common.stats import wilson_interval
from tssac_core.experiments.summary import (
    TRANSFER_ROLES,
    AlgorithmSummary,
    OverSeeds,
    RoleComparison,
    StepsFigures,
    Summary,
    TailPool,
    TailRow,
    TrainingBudget,
    TransferFigures,
)
from tssac_core.sim.scenario import ROLES

GUIDANCE_NAME = "guidance controller"


def _rate(stats: OverSeeds) -> str:
    if stats.mean is None:
        return "—"
    return f"{100 * stats.mean:.1f}%" + (f" ± {100 * stats.std:.1f}" if stats.std is not None else "")


def _cost(stats: OverSeeds) -> str:
    if stats.mean is None:
        return "—"
    return f"{stats.mean:.2f}" + (f" ± {stats.std:.2f}" if stats.std is not None else "")


def _steps(figures: StepsFigures) -> str:
    if figures.mean_steps is None:
        return "—"
    bound = ">= " if figures.mean_is_lower_bound else ""
    return f"{bound}{figures.mean_steps:,.0f} (reached in {figures.reached} of {figures.seeds} seeds)"


def _minutes(stats: OverSeeds) -> str:
    if stats.mean is None:
        return "—"
    return f"{stats.mean / 60:.0f} min" + (f" ± {stats.std / 60:.0f}" if stats.std is not None else "")


def _budget(training: TrainingBudget) -> str:
    """The training budget beside the table: every algorithm alike, and how it compares with the paper's."""
    epochs, paper = training.epochs_per_role, training.paper_epochs_per_role
    text = (
        f"Training budget, the same for every algorithm: {epochs} epochs x {training.steps_per_epoch:,} learner "
        f"decisions "
        f"per role (one decision per {training.action_repeat} world steps of 0.1 s)."
    )
    if epochs < paper:
        text += (
            f" **Shrunk from the paper's {paper} epochs** to fit the grid on this machine: "
            f"{epochs / paper:.0%} of its training."
        )
    return text


def _tail_rate(t: TailPool, of_seeds: int | None = None) -> str:
    """Pooled success with its 95% Wilson interval; with ``of_seeds``, how many of the finished seeds it pools (if
    not all)."""
    if t.figures is None:
        return "—"
    lo, hi = t.figures.success_interval95
    text = f"{100 * t.figures.success_rate:.1f}% ({100 * lo:.1f}-{100 * hi:.1f})"
    return text + (f" [{t.seeds} of {of_seeds} seeds]" if of_seeds is not None and t.seeds < of_seeds else "")


def _tail_cost(t: TailPool) -> str:
    if t.figures is None:
        return "—"
    lo, hi = t.figures.mean_cost_interval95
    return f"{t.figures.mean_cost:.2f} ({lo:.2f}-{hi:.2f})"


def _percent(value: float | None) -> str:
    return f"{100 * value:.1f}%" if value is not None else "—"


def _largest(values: list[float]) -> str:
    return ", ".join(f"{v:,.0f}" for v in values if v > 0) or "—"


def _tail_rows(summary: Summary) -> list[tuple[str, TailPool | None, TailPool | None, int | None, TailRow | None]]:
    """Per row of the tail columns: name, the tail and the tail with the monitor, the finished seeds (None: the
    guidance controller), and the algorithm's tail row (its seeds)."""
    rows: list[tuple[str, TailPool | None, TailPool | None, int | None, TailRow | None]] = [
        (
            a.name,
            a.tail.pool if a.tail is not None else None,
            a.tail_monitor.pool if a.tail_monitor is not None else None,
            len(a.seeds),
            a.tail,
        )
        for a in summary.algorithms.values()
    ]
    g = summary.guidance
    rows.append((GUIDANCE_NAME, g.tail, g.tail_monitor, None, None))
    return rows


def tail_columns(summary: Summary) -> tuple[list[str], dict[str, list[str]]]:
    """The main table's extra columns for the tail evaluation (and the monitor): headers, and cells per row name."""
    ev = summary.evaluation
    if not ev.tail_episodes:
        return [], {}
    n = ev.tail_episodes
    headers = [
        f"{n} layouts: success rate (95% interval)",
        f"{n} layouts: average cost (95% interval)",
        f"{n} layouts: within C",
    ]
    if ev.tail_monitor:
        headers += [
            "with monitor: success rate (95% interval)",
            "with monitor: average cost (95% interval)",
            "with monitor: time under backup",
        ]
    rows = {}
    for name, tail, on, seeds, _ in _tail_rows(summary):
        assert tail is not None, "a grid with tail_episodes flies the tail"
        cells = [
            _tail_rate(tail, seeds),
            _tail_cost(tail),
            _percent(tail.figures.within_cost_limit if tail.figures is not None else None),
        ]
        if ev.tail_monitor:
            assert on is not None, "a grid with tail_monitor flies it"
            cells += [
                _tail_rate(on, seeds),
                _tail_cost(on),
                _percent(on.monitor.backup_time_fraction if on.monitor is not None else None),
            ]
        rows[name] = cells
    return headers, rows


def tail_markdown(summary: Summary) -> list[str]:
    """The section on the tail evaluation: what its columns are, how to fly one again, and its tail figures."""
    ev = summary.evaluation
    n, seed, monitor = ev.tail_episodes, ev.tail_seed, ev.tail_monitor
    assert n is not None and seed is not None, "only for a grid with tail_episodes"
    lines = [
        "",
        f"## {n} layouts per team, with intervals{', and with the runtime-assurance monitor' if monitor else ''}",
        "",
        f'The columns "{n} layouts": every team flies {n} more layouts of `{ev.scenario}`, mission k on the '
        f"layout of seed {seed} + k, as `tssac_core.evaluate` draws them (layout seeds {seed}-{seed + n - 1}: never "
        f"used in training, in epoch selection or in the {ev.episodes} layouts above), the same layouts for every "
        f"team. An algorithm's seeds are pooled into one sample ({n} missions per seed): success with its 95% Wilson "
        "interval, the mean hazard cost per UAV with its 95% bootstrap interval over missions (a mission's three UAVs "
        "resampled together; `tssac_core.common.stats`), and the share of UAV-missions within C. Where a row pools "
        "fewer seeds than it has, the success cell says so.",
    ]
    if monitor:
        lines += [
            "",
            'The columns "with monitor": the same layouts flown again through the runtime-assurance monitor '
            "(`python -m tssac_core.evaluate --shield`, docs/runtime_assurance.md), which hands a UAV to its backup "
            "manoeuvre when the path it predicts would enter a radar's disk or leave the area: success, cost, and the "
            "share of flight time under the backup.",
        ]
    lines += [
        "",
        "Each run's evaluations are cached beside it (`runs/<run>/eval_tail.json`"
        + (", `eval_tail_monitor.json`" if monitor else "")
        + "; "
        "the guidance controller's in `guidance/`), with the worst missions' layout seeds; one run again: `python -m "
        f"tssac_core.evaluate --models runs/<run> --scenario {ev.scenario} --episodes {n} --seed {seed}"
        f"{' [--shield]' if monitor else ''}`, one mission of it `--seed {seed} --mission K`.",
        "",
        "| algorithm | seeds flown | per seed: success, cost | UAV-missions over C | CVaR95 | largest | "
        "UAVs that left the area |"
        + (
            " with monitor: over C | with monitor: UAVs that left the area | "
            "with monitor: interventions per UAV-mission |"
            if monitor
            else ""
        ),
        "| --- | --- | --- | --- | --- | --- | --- |" + (" --- | --- | --- |" if monitor else ""),
    ]
    for name, tail, on, _, row in _tail_rows(summary):
        assert tail is not None
        f = tail.figures
        flown = ", ".join(map(str, row.flown_seeds)) if row is not None else ""
        if f is None:
            cells = [flown or "none", "—", "—", "—", "—", "—"]
        else:
            per_seed = "; ".join(
                f"{s}: {100 * x.success_rate:.1f}%, {x.mean_cost:.2f}"
                for s, x in (row.per_seed.items() if row is not None else ())
            )
            cells = [
                "—" if row is None else flown,
                per_seed or "—",
                f"{f.over_limit} of {3 * tail.missions}",
                f"{f.cvar95_cost:.1f}",
                _largest(f.largest),
                str(f.left_area),
            ]
        if monitor:
            assert on is not None
            if on.figures is not None and on.monitor is not None:
                cells += [
                    f"{on.figures.over_limit} of {3 * on.missions}",
                    str(on.figures.left_area),
                    f"{on.monitor.interventions_per_uav_mission:.2f}",
                ]
            else:
                cells += ["—", "—", "—"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


CASCADE = tuple(role.value for role in ROLES)
"""The roles in the order their tasks nest (eq. 9): the detect UAV identifies the target only while the radar is on,
which the decoy's ring switches on, and the strike UAV hits only an identified target."""


def _share(k: int, n: int) -> str:
    """k of n with its 95% Wilson interval."""
    if n == 0:
        return "— (0 of 0)"
    w = wilson_interval(k, n)
    return f"{100 * w.value:.1f}% ({100 * w.low:.1f}-{100 * w.high:.1f}; {k:,} of {n:,})"


def cascade_markdown(summary: Summary) -> list[str]:
    """Where the tail's missions stop: each role's task, given the task before it (the tasks nest, so a role's
    missions are those in which the role before it finished)."""
    n = summary.evaluation.tail_episodes
    lines = [
        "",
        "## Where the missions stop: each role's task, given the one before it",
        "",
        f"The {n} layouts above, monitor off, pooled over the seeds. The tasks nest (eq. 9): the detect UAV identifies "
        "the target only while the decoy holds its ring (which switches the radar on), and the strike UAV hits only "
        "an identified target; so a mission succeeds in the share of the first column times the second times the "
        "third, and the column where a row is low is where its missions stop. Each share with its 95% Wilson interval "
        "and its count.",
        "",
        "| algorithm | decoy's task | detect's, given the decoy's | strike's, given the detect's | mission success |",
        "| --- | --- | --- | --- | --- |",
    ]
    lines += [cascade_row(name, tail) for name, tail, _, _, _ in _tail_rows(summary)]
    return lines


def cascade_row(name: str, tail: TailPool | None) -> str:
    """One row of :func:`cascade_markdown`: each role's task among the missions in which the role before it finished."""
    f = tail.figures if tail is not None else None
    if tail is None or f is None or f.tasks_finished is None:
        return f"| {name} | — | — | — | — |"
    done = [f.tasks_finished[role] for role in CASCADE]
    before = [tail.missions, *done[:-1]]
    return f"| {name} | " + " | ".join(_share(k, m) for k, m in zip(done, before)) + f" | {_tail_rate(tail)} |"


def _main_row(a: AlgorithmSummary, tail_cells: list[str]) -> str:
    paper = a.paper
    p_rate, p_cost = (f"{100 * paper.success_rate:.0f}%", f"{paper.mean_cost:.1f}") if paper else ("—", "—")
    r = a.random
    return (
        f"| {a.name} | {len(a.seeds)} | {_rate(r.success_rate)} | {_cost(r.mean_cost)} "
        f"| {_rate(r.within_cost_limit)} | {p_rate} | {p_cost} | "
        + "".join(f"{c} | " for c in tail_cells)
        + f"{_minutes(a.training_wall_s)} |"
    )


def _speedup(r: RoleComparison, digits: int) -> str:
    if r.speedup is None:
        return "—"
    return f"{'>= ' if r.speedup_is_lower_bound else ''}{r.speedup:.{digits}f}x"


def table_markdown(summary: Summary) -> str:
    """table4.md: Table 4 beside the paper's, the generalisation figures and the transfer speed-up."""
    ev = summary.evaluation
    tail_headers, tail_cells = tail_columns(summary)
    lines = [
        "# Table 4: success rate and average cost",
        "",
        f"Grid `{summary.grid}`. Every team flies the same {ev.episodes} layouts of `{ev.scenario}` "
        f"(layout seed {ev.seed}, never used in training; {ev.layouts}). Ours: mean ± sample standard "
        "deviation over the "
        "finished seeds. Success = the target was hit (all three tasks). Average cost = hazard cost per UAV "
        f"per mission (limit C = {summary.cost_limit:g} per UAV); within C = the share of UAV-missions whose own "
        f"cost "
        "is at most C. The paper's figures are its Table 4.",
        "",
        _budget(summary.training),
        "",
        "| algorithm | seeds | success rate | average cost | within C | paper: success rate | paper: average cost | "
        + "".join(f"{h} | " for h in tail_headers)
        + "training wall time per seed |",
        "| --- | --- | --- | --- | --- | --- | --- | " + "--- | " * len(tail_headers) + "--- |",
    ]
    for a in summary.algorithms.values():
        lines.append(_main_row(a, tail_cells.get(a.name, [])))
    g = summary.guidance.random
    lines.append(
        f"| {GUIDANCE_NAME} | — | {100 * g.success_rate:.1f}% | {g.mean_cost:.2f} | "
        f"{100 * g.within_cost_limit:.1f}% | — | — | "
        + "".join(f"{c} | " for c in tail_cells.get(GUIDANCE_NAME, []))
        + "— |"
    )
    if tail_headers:
        lines += tail_markdown(summary)
        lines += cascade_markdown(summary)
    lines += [
        "",
        "## The mean cost against the limit",
        "",
        f"Every seed's {ev.episodes} missions pooled: the mean cost per UAV per mission with a 95% bootstrap "
        f"interval over "
        "missions, how many UAV-missions cost more than C, and the largest single costs (steps of 0.1 s inside a "
        "radar). A "
        "few long stays inside a radar make the mean: where the interval spans C, these layouts cannot tell on which "
        "side of "
        "the limit the algorithm is.",
        "",
        "| algorithm | UAV-missions | mean cost | 95% interval | over C | largest |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for a in summary.algorithms.values():
        c = a.random.pooled_cost
        if c.mean is not None and c.ci95 is not None:
            largest = ", ".join(f"{v:.0f}" for v in c.largest if v > 0) or "—"
            lines.append(
                f"| {a.name} | {c.uav_missions} | {c.mean:.2f} | {c.ci95[0]:.2f}-{c.ci95[1]:.2f} "
                f"| {c.over_limit} | {largest} |"
            )
    if summary.left_out:
        lines += [
            "",
            f"Left out (not finished, or a run with other settings than the grid: see --dry-run): "
            f"{', '.join(summary.left_out)}.",
        ]
    if summary.guidance.generalization is not None:
        lines += [
            "",
            "## Generalisation (figure 11)",
            "",
            f"The same teams on `{ev.generalization_scenario}` ({ev.episodes} layouts, seed {ev.seed}).",
            "",
            "| algorithm | seeds | success rate | average cost | within C |",
            "| --- | --- | --- | --- | --- |",
        ]
        for a in summary.algorithms.values():
            gen = a.generalization
            assert gen is not None, "every row has the grid's evaluations"
            lines.append(
                f"| {a.name} | {len(a.seeds)} | {_rate(gen.success_rate)} | {_cost(gen.mean_cost)} | "
                f"{_rate(gen.within_cost_limit)} |"
            )
        gg = summary.guidance.generalization
        lines.append(
            f"| {GUIDANCE_NAME} | — | {100 * gg.success_rate:.1f}% | {gg.mean_cost:.2f} | "
            f"{100 * gg.within_cost_limit:.1f}% |"
        )
    t = summary.transfer_speedup
    lines += [
        "",
        "## Transfer inside the grid's curricula",
        "",
        f"Learner decisions (`env_steps` in metrics.csv) until the first epoch with task success >= "
        f"{100 * t.threshold:.0f}%, "
        "mean over the finished seeds, in the grid's own runs (each role beside that run's earlier roles). A seed that "
        "never "
        "got there counts with its role's total decisions, so such a mean is a lower bound (>=)."
        + (
            " The transfer experiment (last section) measures it beside the same trained earlier roles."
            if summary.transfer_experiment is not None
            else ""
        ),
        "",
        "| role | tssac | sac_lag | speed-up (sac_lag / tssac) |",
        "| --- | --- | --- | --- |",
    ]
    for role in TRANSFER_ROLES:
        r = t.roles[role]
        lines.append(f"| {role} | {_steps(r.with_transfer)} | {_steps(r.without_transfer)} | {_speedup(r, 2)} |")
    lines += [
        "",
        "Task success in training averaged over the role's epochs (the area under its learning curve; mean ± "
        "standard deviation over seeds): with transfer, the role starts from the previous role's networks.",
        "",
        "| role | tssac (transfer) | sac_lag (from scratch) |",
        "| --- | --- | --- |",
    ]
    for role in TRANSFER_ROLES:
        r = t.roles[role]
        lines.append(
            f"| {role} | {_rate(r.with_transfer.mean_task_success)} | {_rate(r.without_transfer.mean_task_success)} |"
        )
    if summary.transfer_experiment is not None:
        lines += transfer_experiment_markdown(summary.transfer_experiment)
    return "\n".join(lines) + "\n"


def transfer_experiment_markdown(x: TransferFigures) -> list[str]:
    """The transfer experiment's table: decisions to the level per seed and their mean, each side, each role."""
    first = x.per_role[x.roles[0]]
    with_name = first.with_transfer.entry or "with"
    without_name = first.without_transfer.entry or "without"
    cap = x.epochs * x.steps_per_epoch
    lines = [
        "",
        "## Transfer experiment: decisions to the level, with and without transfer",
        "",
        f"Each role trained alone with the same trained earlier roles flying (the actors in `{x.teammates}` when the "
        f"runs trained: a run records the directory, not its files), stopped at the first "
        f"epoch whose task success in training reached {100 * x.threshold:.0f}%, at most {x.epochs} epochs "
        f"({cap:,} decisions). `{with_name}` starts from the previous role's networks in `{x.teammates}` (TSSAC's "
        f"transfer); "
        f"`{without_name}` starts from scratch. Per seed, then the mean; a seed that never got there counts with its "
        f"{cap:,} decisions, so such a mean is a lower bound (>=).",
        "",
        f"| role | {with_name} (transfer): per seed | mean | {without_name} (from scratch): per seed | mean | speed-up "
        f"|",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for role in x.roles:
        r = x.per_role[role]
        lines.append(
            f"| {role} | {_per_seed(r.with_transfer)} | {_mean_steps(r.with_transfer)} | "
            f"{_per_seed(r.without_transfer)} | {_mean_steps(r.without_transfer)} | {_speedup(r, 1)} |"
        )
    return lines


def _per_seed(figures: StepsFigures) -> str:
    if not figures.seeds:
        return "—"
    return ", ".join(
        f"{v:,}" if v is not None else f"not in {figures.counted[seed]:,}" for seed, v in figures.per_seed.items()
    )


def _mean_steps(figures: StepsFigures) -> str:
    if figures.mean_steps is None:
        return "—"
    return f"{'>= ' if figures.mean_is_lower_bound else ''}{figures.mean_steps:,.0f}"


def write_report(summary: Summary, results: Path) -> tuple[Path, Path]:
    """Write ``table4.md`` and ``experiments.json`` under ``results``."""
    results.mkdir(parents=True, exist_ok=True)
    table = results / "table4.md"
    tmp = table.with_name(table.name + ".tmp")
    tmp.write_text(table_markdown(summary))
    tmp.replace(table)
    data = results / "experiments.json"
    write_json(data, summary.to_json())
    return table, data

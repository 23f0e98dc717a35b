"""``table4.md``: Table 4 beside the paper's, the tail and monitor columns, the mean cost against the limit, the
generalisation figures (and the generalisation tail's section) and the transfer speed-up, written from a
:class:`~tssac_core.experiments.summary.Summary`; and :func:`write_report`, which writes it with
``experiments.json``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tssac_core.common.cli import write_json
from tssac_core.common.stats import wilson_interval
from tssac_core.experiments.evaluations import EvalLabel
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


def _with_rule(header: str) -> list[str]:
    """A markdown table's header line and the rule under it, one ``---`` per column of the header."""
    return [header, "|" + " --- |" * (header.count("|") - 1)]


@dataclass(frozen=True)
class TailLine:
    """One row's figures of a tail evaluation: an algorithm's seeds pooled, or the guidance controller's."""

    name: str
    pool: TailPool | None
    """The pooled sample (None: the grid does not fly this tail)."""
    seeds: int | None
    """The algorithm's finished seeds (None: the guidance controller)."""
    row: TailRow | None
    """The algorithm's tail row, which seeds it pools and their figures (None: the guidance controller)."""


def tail_lines(summary: Summary, label: EvalLabel) -> list[TailLine]:
    """The lines of the tail evaluation ``label``: every algorithm's, then the guidance controller's."""
    lines = []
    for a in summary.algorithms.values():
        row = a.tail_of(label)
        lines.append(TailLine(a.name, row.pool if row is not None else None, len(a.seeds), row))
    lines.append(TailLine(GUIDANCE_NAME, summary.guidance.tail_of(label), None, None))
    return lines


def _pooled_cells(line: TailLine) -> list[str]:
    """Pooled success and mean cost per UAV, each with its 95% interval (the success cell says how many of the
    finished seeds it pools, if not all)."""
    assert line.pool is not None, "a grid flies the tails it names"
    return [_tail_rate(line.pool, line.seeds), _tail_cost(line.pool)]


def _within(t: TailPool) -> str:
    return _percent(t.figures.within_cost_limit if t.figures is not None else None)


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
    for line, on in zip(tail_lines(summary, EvalLabel.TAIL), tail_lines(summary, EvalLabel.TAIL_MONITOR)):
        assert line.pool is not None, "a grid with tail_episodes flies the tail"
        cells = [*_pooled_cells(line), _within(line.pool)]
        if ev.tail_monitor:
            assert on.pool is not None, "a grid with tail_monitor flies it"
            backup = on.pool.monitor.backup_time_fraction if on.pool.monitor is not None else None
            cells += [*_pooled_cells(on), _percent(backup)]
        rows[line.name] = cells
    return headers, rows


DETAIL_HEADER = (
    "seeds flown | per seed: success, cost | within C per role: "
    + ", ".join(role.value for role in ROLES)
    + " | UAV-missions over C | CVaR95 | largest | UAVs that left the area |"
)
"""The columns of :func:`_detail_cells`."""


def _detail_cells(line: TailLine) -> list[str]:
    """Which seeds a tail pools and each seed's success and cost, then the pooled sample's tail: each role's share of
    UAV-missions within C, the UAV-missions over C, their costs' CVaR95, the largest costs (the worst UAV-missions)
    and the UAVs that left the area."""
    tail, row = line.pool, line.row
    assert tail is not None, "a grid flies the tails it names"
    f = tail.figures
    flown = ", ".join(map(str, row.flown_seeds)) if row is not None else ""
    if f is None:
        return [flown or "none", "—", "—", "—", "—", "—", "—"]
    per_seed = "; ".join(
        f"{s}: {100 * x.success_rate:.1f}%, {x.mean_cost:.2f}"
        for s, x in (row.per_seed.items() if row is not None else ())
    )
    return [
        "—" if row is None else flown,
        per_seed or "—",
        ", ".join(_percent(f.within_cost_limit_per_role[role.value]) for role in ROLES),
        f"{f.over_limit} of {3 * tail.missions}",
        f"{f.cvar95_cost:.1f}",
        _largest(f.largest),
        str(f.left_area),
    ]


def _layouts_text(scenario: str, n: int, seed: int, episodes: int) -> str:
    """Which layouts a tail flies (after "every team flies N [more] ")."""
    return (
        f"layouts of `{scenario}`, mission k on the layout of seed {seed} + k, as `tssac_core.evaluate` draws them "
        f"(layout seeds {seed}-{seed + n - 1}: never used in training, in epoch selection or in the {episodes} layouts "
        "above), the same layouts for every team"
    )


def _pooled_text(n: int) -> str:
    """How a tail's figures are pooled over an algorithm's seeds."""
    return (
        f"An algorithm's seeds are pooled into one sample ({n} missions per seed): success with its 95% Wilson "
        "interval, the mean hazard cost per UAV with its 95% bootstrap interval over missions (a mission's three UAVs "
        "resampled together; `tssac_core.common.stats`), and the share of UAV-missions within C. Where a row pools "
        "fewer seeds than it has, the success cell says so."
    )


def _fly_again_text(caches: list[str], scenario: str, n: int, seed: int, monitor: bool) -> str:
    """Where a tail's evaluations are cached and how to fly one run's again, or one of its missions."""
    return (
        f"Each run's evaluation{'s are' if len(caches) > 1 else ' is'} cached beside it (`runs/<run>/{caches[0]}`"
        + "".join(f", `{c}`" for c in caches[1:])
        + "; the guidance controller's in `guidance/`), with the worst missions' layout seeds; one run again: "
        f"`python -m tssac_core.evaluate --models runs/<run> --scenario {scenario} --episodes {n} --seed {seed}"
        f"{' [--shield]' if monitor else ''}`, one mission of it `--seed {seed} --mission K`."
    )


def tail_markdown(summary: Summary) -> list[str]:
    """The section on the tail evaluation: what its columns are, how to fly one again, and its tail figures."""
    ev = summary.evaluation
    n, seed, monitor = ev.tail_episodes, ev.tail_seed, bool(ev.tail_monitor)
    assert n is not None and seed is not None, "only for a grid with tail_episodes"
    labels = [EvalLabel.TAIL, *([EvalLabel.TAIL_MONITOR] if monitor else [])]
    lines = [
        "",
        f"## {n} layouts per team, with intervals{', and with the runtime-assurance monitor' if monitor else ''}",
        "",
        f'The columns "{n} layouts": every team flies {n} more {_layouts_text(ev.scenario, n, seed, ev.episodes)}. '
        + _pooled_text(n),
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
        _fly_again_text([f"eval_{label.value}.json" for label in labels], ev.scenario, n, seed, monitor),
        "",
        *_with_rule(
            f"| algorithm | {DETAIL_HEADER}"
            + (
                " with monitor: over C | with monitor: UAVs that left the area | "
                "with monitor: interventions per UAV-mission |"
                if monitor
                else ""
            )
        ),
    ]
    for line, on in zip(tail_lines(summary, EvalLabel.TAIL), tail_lines(summary, EvalLabel.TAIL_MONITOR)):
        cells = _detail_cells(line)
        if monitor:
            assert on.pool is not None
            if on.pool.figures is not None and on.pool.monitor is not None:
                cells += [
                    f"{on.pool.figures.over_limit} of {3 * on.pool.missions}",
                    str(on.pool.figures.left_area),
                    f"{on.pool.monitor.interventions_per_uav_mission:.2f}",
                ]
            else:
                cells += ["—", "—", "—"]
        lines.append(f"| {line.name} | " + " | ".join(cells) + " |")
    return lines


def generalization_tail_markdown(summary: Summary) -> list[str]:
    """The section on the generalisation tail: its layouts, how to fly one again, and per row the pooled success and
    cost with their intervals, the within-C share and the tail figures of :func:`_detail_cells`."""
    ev = summary.evaluation
    n, seed, scenario = ev.generalization_tail_episodes, ev.generalization_tail_seed, ev.generalization_scenario
    assert n is not None and seed is not None and scenario is not None, "only for a grid with a generalization tail"
    label = EvalLabel.GENERALIZATION_TAIL
    lines = [
        "",
        f"## {n} layouts of the generalisation scenario per team, with intervals",
        "",
        f"Every team flies {n} {_layouts_text(scenario, n, seed, ev.episodes)}, without the monitor. "
        + _pooled_text(n)
        + " The further columns: which seeds a row pools and each seed's success and cost, each role's share of its "
        "UAV-missions within C, the UAV-missions over C, "
        "the CVaR95 of their costs, the largest costs (the worst UAV-missions, in steps of 0.1 s inside a radar) and "
        "the UAVs that left the area.",
        "",
        _fly_again_text([f"eval_{label.value}.json"], scenario, n, seed, monitor=False),
        "",
        *_with_rule(
            f"| algorithm | success rate (95% interval) | average cost (95% interval) | within C | {DETAIL_HEADER}"
        ),
    ]
    for line in tail_lines(summary, label):
        assert line.pool is not None, "a grid with generalization_tail_episodes flies it"
        cells = [*_pooled_cells(line), _within(line.pool), *_detail_cells(line)]
        lines.append(f"| {line.name} | " + " | ".join(cells) + " |")
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
        *_with_rule(
            "| algorithm | decoy's task | detect's, given the decoy's | strike's, given the detect's | "
            "mission success |"
        ),
    ]
    lines += [cascade_row(line.name, line.pool) for line in tail_lines(summary, EvalLabel.TAIL)]
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


def cost_markdown(summary: Summary) -> list[str]:
    """The mean cost against the limit: every seed's missions pooled, with intervals."""
    ev = summary.evaluation
    lines: list[str] = [
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
        *_with_rule("| algorithm | UAV-missions | mean cost | 95% interval | over C | largest |"),
    ]
    for a in summary.algorithms.values():
        c = a.random.pooled_cost
        if c.mean is not None and c.ci95 is not None:
            largest = ", ".join(f"{v:.0f}" for v in c.largest if v > 0) or "—"
            lines.append(
                f"| {a.name} | {c.uav_missions} | {c.mean:.2f} | {c.ci95[0]:.2f}-{c.ci95[1]:.2f} "
                f"| {c.over_limit} | {largest} |"
            )
    return lines


def generalization_markdown(summary: Summary) -> list[str]:
    """Figure 11's table: the same teams on the generalisation scenario (none without one)."""
    ev = summary.evaluation
    if summary.guidance.generalization is None:
        return []
    lines = [
        "",
        "## Generalisation (figure 11)",
        "",
        f"The same teams on `{ev.generalization_scenario}` ({ev.episodes} layouts, seed {ev.seed}).",
        "",
        *_with_rule("| algorithm | seeds | success rate | average cost | within C |"),
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
    return lines


def transfer_speedup_markdown(summary: Summary) -> list[str]:
    """Transfer inside the grid's curricula: decisions to the task-success threshold, and the area under the
    learning curves."""
    t = summary.transfer_speedup
    lines = [
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
        *_with_rule("| role | tssac | sac_lag | speed-up (sac_lag / tssac) |"),
    ]
    for role in TRANSFER_ROLES:
        r = t.roles[role]
        lines.append(f"| {role} | {_steps(r.with_transfer)} | {_steps(r.without_transfer)} | {_speedup(r, 2)} |")
    lines += [
        "",
        "Task success in training averaged over the role's epochs (the area under its learning curve; mean ± "
        "standard deviation over seeds): with transfer, the role starts from the previous role's networks.",
        "",
        *_with_rule("| role | tssac (transfer) | sac_lag (from scratch) |"),
    ]
    for role in TRANSFER_ROLES:
        r = t.roles[role]
        lines.append(
            f"| {role} | {_rate(r.with_transfer.mean_task_success)} | {_rate(r.without_transfer.mean_task_success)} |"
        )
    return lines


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
        *_with_rule(
            "| algorithm | seeds | success rate | average cost | within C | paper: success rate | "
            "paper: average cost | " + "".join(f"{h} | " for h in tail_headers) + "training wall time per seed |"
        ),
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
    lines += cost_markdown(summary)
    if summary.left_out:
        lines += [
            "",
            f"Left out (not finished, or a run with other settings than the grid: see --dry-run): "
            f"{', '.join(summary.left_out)}.",
        ]
    lines += generalization_markdown(summary)
    if ev.generalization_tail_episodes:
        lines += generalization_tail_markdown(summary)
    lines += transfer_speedup_markdown(summary)
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
        *_with_rule(
            f"| role | {with_name} (transfer): per seed | mean | {without_name} (from scratch): per seed | mean | "
            "speed-up |"
        ),
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

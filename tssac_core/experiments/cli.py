"""``python -m tssac_core.experiments``: train a grid of (algorithm x seed) runs, evaluate them, write Table 4 and
figures 7-12.

Examples::

    python -m tssac_core.experiments --grid experiments/paper.yaml --dry-run      # the jobs and their status
    python -m tssac_core.experiments --grid experiments/paper.yaml --jobs 2       # train what is missing, then report
    python -m tssac_core.experiments --grid experiments/paper.yaml --jobs 2 --finish-by 17:30  # only what ends by 17:30
    python -m tssac_core.experiments --grid experiments/paper.yaml --jobs 2 --only 'tssac-*' --only 'sac_lag-*'  #
    these first
    python -m tssac_core.experiments --grid experiments/paper.yaml --report-only  # report on what has finished
    python -m tssac_core.experiments --grid experiments/paper.yaml --report-only --cached-tail  # no new tail flights
    python -m tssac_core.experiments --grid experiments/paper.yaml --compact      # slim finished runs to commit them

The grid file's format is in :mod:`tssac_core.experiments.grid`. Each job is a
``python -m tssac_core.train --config`` process, handed the job's `TrainConfig` as JSON, writing
``<results>/runs/<name>-seed<S>/`` (its output in ``train.log`` there); a finished job is not run again and an
interrupted one is continued with ``--resume``, so running the command again after a crash, Ctrl-C or reboot
picks up where it stopped (:mod:`tssac_core.train.jobs.runner`). Then every finished
team is evaluated (:mod:`tssac_core.experiments.evaluations`, cached beside it), summarised
(:mod:`tssac_core.experiments.summary`), and ``<results>/table4.md`` (:mod:`tssac_core.experiments.table`),
``<results>/experiments.json`` and the figures (:mod:`tssac_core.experiments.figures`) are written.
"""

from __future__ import annotations

import argparse
import fnmatch
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from tssac_core.common.cli import UsageError, command_description, run
from tssac_core.experiments.deadline import deadline_filter, parse_finish_by
from tssac_core.experiments.evaluations import EvalLabel, eval_specs, evaluate_all, fly_one
from tssac_core.experiments.grid import Grid, load_grid
from tssac_core.experiments.learning_curves import read_metrics
from tssac_core.experiments.summary import summarise
from tssac_core.experiments.table import write_report
from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.sim.missions import MissionResults
from tssac_core.sim.scenario import Scenario, load
from tssac_core.train.jobs.executors import EXECUTORS, LOCAL, RAY, execute
from tssac_core.train.jobs.job import Job
from tssac_core.train.jobs.runner import Launch, Status, command, is_finished, job_state

Say = Callable[[str], None]


def say(line: str) -> None:
    print(line, flush=True)


def train(
    grid: Grid,
    results: Path,
    parallel: int | None,
    report: Say = say,
    finish_by: float | None = None,
    only: Sequence[str] = (),
    executor: str = LOCAL,
    ray_target: RayTarget | None = None,
) -> list[Launch]:
    """Run every job that is not finished (with ``only``, of the jobs those patterns name; with ``finish_by``,
    a POSIX time: those expected to finish by then) with ``executor``, ``parallel`` at once (None: the
    executor's default); refuses (UsageError) if a run directory holds other settings."""
    states = [job_state(job) for job in selected_jobs(grid, results, only)]
    conflicts = [s for s in states if s.status is Status.CONFLICT]
    if conflicts:
        more = f" (and {len(conflicts) - 1} more: see --dry-run)" if len(conflicts) > 1 else ""
        raise UsageError(
            f"{conflicts[0].job.out} holds a run with other settings than {grid.source} ({conflicts[0].detail}); "
            f"move it away or choose another --results{more}"
        )
    todo = sum(s.status is not Status.FINISHED for s in states)
    at_once = f"{parallel} at a time" if parallel is not None else "as many at a time as the CPUs hold"
    on_ray = " on Ray" if executor == RAY else ""
    report(f"{len(states)} jobs: {len(states) - todo} finished, {todo} to run, {at_once}{on_ray}")
    if finish_by is None:
        return execute(states, executor, parallel, report, ray_target=ray_target)
    report(f"starting only jobs expected to finish by {time.strftime('%Y-%m-%d %H:%M', time.localtime(finish_by))}")
    return execute(states, executor, parallel, report, deadline_filter(states, finish_by), ray_target=ray_target)


def all_jobs(grid: Grid, results: Path) -> list[Job]:
    """The teams of Table 4, then the transfer experiment's runs."""
    return [*grid.jobs(results), *grid.transfer_jobs(results)]


def selected_jobs(grid: Grid, results: Path, only: Sequence[str] = ()) -> list[Job]:
    """The grid's jobs (in the grid's order) whose names match one of the shell patterns ``only`` (all of
    them without patterns); refuses (UsageError) a pattern that matches none."""
    jobs = all_jobs(grid, results)
    for pattern in only:
        if not any(fnmatch.fnmatchcase(job.name, pattern) for job in jobs):
            raise UsageError(
                f"--only {pattern!r} matches none of the jobs of {grid.source} (see --dry-run for their names)"
            )
    return [job for job in jobs if not only or any(fnmatch.fnmatchcase(job.name, pattern) for pattern in only)]


def make_report(grid: Grid, results: Path, report: Say = say, cached_tail: bool = False) -> list[Path]:
    """Evaluate the finished teams (cached; with ``cached_tail`` the tail evaluations only from their caches), write
    table4.md, experiments.json and the figures; returns the files. The evaluations fly with one torch thread."""
    import torch  # torch and matplotlib here, not above: --help and --dry-run answer without them

    from tssac_core.experiments.figures import plot_figures

    torch.set_num_threads(1)
    jobs = grid.jobs(results)
    states = [job_state(job) for job in jobs]
    for s in states:
        if s.status is Status.CONFLICT:
            report(f"warning: leaving out {s.job.out}: other settings than the grid ({s.detail})")
    finished = [s.job for s in states if s.status is Status.FINISHED]
    report(f"report on {len(finished)} of {len(jobs)} runs")
    evaluations = evaluate_all(grid, finished, results, report, cached_tail)
    transfer_runs = [job for job in grid.transfer_jobs(results) if job_state(job).status is Status.FINISHED]
    summary = summarise(grid, jobs, finished, evaluations, results, transfer_runs)
    table, data = write_report(summary, results)
    curves = {e.name: [read_metrics(j.out) for j in finished if j.entry == e] for e in grid.algos}
    curves = {name: runs for name, runs in curves.items() if runs}
    per_episode = {
        e.name: [evaluations[(j.name, EvalLabel.RANDOM)].per_episode for j in finished if j.entry == e]
        for e in grid.algos
    }  # 50 layouts
    per_episode = {name: runs for name, runs in per_episode.items() if runs}
    figures = plot_figures(results, summary, curves, per_episode, mission_for_fig9(grid, finished))
    for path in (table, data, *figures):
        report(f"wrote {path}")
    return [table, data, *figures]


def mission_for_fig9(grid: Grid, finished: list[Job]) -> tuple[MissionResults, Scenario, str] | None:
    """The first evaluation layout flown by the first finished TSSAC team (else the first finished team)."""
    if not finished:
        return None
    job = next((j for j in finished if j.entry.algo == "tssac"), finished[0])
    spec = eval_specs(grid)[0]
    return (
        fly_one(job.out, spec),
        load(spec.scenario),
        f"{job.name}: {spec.scenario.name}, layout 1 of seed {spec.seed}",
    )


def dry_run(grid: Grid, results: Path, report: Say = say, only: Sequence[str] = ()) -> None:
    """Print every job (with ``only``, those the patterns name) with its status and what running the grid would do
    with it."""
    for job in selected_jobs(grid, results, only):
        state = job_state(job)
        what = {
            Status.FINISHED: "",
            Status.PARTIAL: " ".join(command(job, resume=True)),
            Status.NEW: " ".join(command(job, resume=False)),
            Status.CONFLICT: state.detail,
        }[state.status]
        report(f"{state.status.value:9s} {job.name:32s} {job.out}  {what}".rstrip())


def compact(grid: Grid, results: Path, report: Say = say) -> None:
    """Finished runs keep what evaluation and the figures need (actors, metrics, logs, plots): each role
    checkpoint loses its learner state (critics, targets, optimiser moments) and the run its resume/
    directory. Partial and conflicting runs are left alone."""
    from tssac_core.deploy.export import compact_checkpoint  # torch: only when compacting

    before = after = 0
    finished = [s.job for s in map(job_state, all_jobs(grid, results)) if s.status is Status.FINISHED]
    for job in finished:
        for role in job.roles:
            b, a = compact_checkpoint(job.out / f"{role}.pt")
            before, after = before + b, after + a
        shutil.rmtree(job.out / "resume", ignore_errors=True)
    report(
        f"compacted {len(finished)} finished runs: role checkpoints {before / 1e6:.1f} MB -> {after / 1e6:.1f} MB, "
        f"resume/ states deleted"
    )


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line, its values checked (UsageError, one line) and --finish-by read as a time."""
    args = build_parser().parse_args(argv)
    check_args(args)
    args.finish_by = parse_finish_by(args.finish_by) if args.finish_by is not None else None
    return args


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m tssac_core.experiments", description=command_description(__doc__))
    p.add_argument("--grid", type=Path, required=True, help="grid file (e.g. experiments/paper.yaml)")
    p.add_argument(
        "--results",
        type=Path,
        default=Path("results"),
        help="output directory (default results/): runs/, table4.md, experiments.json, figures",
    )
    p.add_argument(
        "--jobs",
        type=int,
        help="training jobs at once (each uses the grid's threads); default 1, with --executor ray as many as "
        "the Ray's "
        "CPUs hold",
    )
    p.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=LOCAL,
        help="local (default): processes on this machine; ray: one Ray task per job, on a Ray started inside the "
        "command or on --address (docs/ray.md)",
    )
    p.add_argument(
        "--address",
        metavar="HOST:PORT",
        help="--executor ray: run on this existing Ray cluster ('auto': the one started on this machine with ray "
        "start); the nodes must share the checkout and --results (docs/ray.md)",
    )
    p.add_argument(
        "--cpus",
        type=int,
        metavar="N",
        help="--executor ray without --address: CPUs of the Ray started here (default: the machine's)",
    )
    p.add_argument(
        "--finish-by",
        metavar="HH:MM",
        help="start only jobs expected to finish by then (today, local time; or "
        "'YYYY-MM-DD HH:MM'), by what the grid's finished runs of the same entry took; the rest wait for the next run",
    )
    p.add_argument(
        "--only",
        metavar="PATTERN",
        action="append",
        default=[],
        help="train only the jobs whose names (as --dry-run "
        "prints them, e.g. tssac-seed1) match this shell pattern, e.g. 'sac_lag-*'; may be given more than once",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--report-only", action="store_true", help="train nothing: evaluate and report on the runs that have finished"
    )
    p.add_argument(
        "--cached-tail",
        action="store_true",
        help="fly no new tail evaluation (the grid's evaluation.tail_episodes layouts, "
        "with and without the monitor, and its evaluation.generalization_tail_episodes layouts): report those "
        "already cached, and say which seeds each row lacks",
    )
    mode.add_argument(
        "--dry-run",
        action="store_true",
        help="print the jobs and their status (finished, partial, new, conflict) and exit",
    )
    mode.add_argument(
        "--compact",
        action="store_true",
        help="train nothing: keep only the deployable actor in finished runs' checkpoints "
        "and delete their resume/ states (to commit results; their evaluations stay valid)",
    )
    return p


def check_args(args: argparse.Namespace) -> None:
    """The values no flag's type checks, and the flags that do not go together."""
    if args.jobs is not None and args.jobs < 1:
        raise UsageError("--jobs must be at least 1")
    if args.cpus is not None and args.cpus < 1:
        raise UsageError("--cpus must be at least 1")
    for flag, value in (("--address", args.address), ("--cpus", args.cpus)):
        if value is not None and args.executor != RAY:
            raise UsageError(f"{flag} is for --executor ray")
    if args.address is not None and args.cpus is not None:
        raise UsageError("--cpus sizes the Ray started here; with --address the cluster has its own CPUs")
    trains_nothing = "--report-only" if args.report_only else "--compact" if args.compact else None
    if trains_nothing and (args.only or args.finish_by is not None):
        chooser = "--only" if args.only else "--finish-by"
        raise UsageError(
            f"{chooser} chooses jobs to train, and {trains_nothing} trains nothing (it works on every finished run)"
        )


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    grid = load_grid(args.grid)
    if args.dry_run:
        dry_run(grid, args.results, only=args.only)
        return 0
    if args.compact:
        compact(grid, args.results)
        return 0
    parallel = args.jobs if args.jobs is not None else (None if args.executor == RAY else 1)
    target = RayTarget(args.address, args.cpus)
    launches = (
        []
        if args.report_only
        else train(
            grid,
            args.results,
            parallel,
            finish_by=args.finish_by,
            only=args.only,
            executor=args.executor,
            ray_target=target,
        )
    )
    make_report(grid, args.results, cached_tail=args.cached_tail)
    failed = [launch for launch in launches if launch.returncode != 0 or not is_finished(launch.job)]
    if failed:
        print(
            f"error: {len(failed)} job(s) failed: {', '.join(f.job.name for f in failed)} (see train.log in their run "
            f"directories)",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

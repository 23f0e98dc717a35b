"""``python -m tssac_core.train --seeds 0,1,2 --out DIR``: K seeds of one configuration in one process.

Each seed has its own worlds, replay buffer, validation selector and random streams (`SeedRole`, as a
single run has), and all K share one `KSeedSacLagrangian`: one batched update per step for all seeds.
``DIR/seed<N>/`` holds what ``python -m tssac_core.train --seed N --out DIR/seed<N>`` writes
(config.json with its own seed, metrics.csv, role checkpoints, plots, resume/), and ``DIR/seeds.json``
the list of seeds, from which ``--out DIR --resume`` continues the run.

Seed N of a K-seed run is a valid run of seed N, and the same every time, but not bit for bit the
single run of seed N: the batched matmuls round differently, and a single run's global torch generator
also serves the networks that `Policy.load` builds for teammates and validation, where each seed's
generator here serves its learner only.

Timing columns of metrics.csv: env_steps_per_s and updates_per_s are each seed's own rates (a seed
advances by its steps, or its updates, in the wall time that all K spend on them together).
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tqdm import tqdm

from tssac_core.algos.kseed import KSeedSacLagrangian
from tssac_core.cli import UsageError, write_json
from tssac_core.observation import ObservationMode
from tssac_core.policy import learner_state
from tssac_core.scenario import Role, Scenario
from tssac_core.train import (
    SAC_FAMILY,
    EpochLog,
    TrainConfig,
    log_transfer,
    open_seed_role,
    prepare_run,
    read_resume_state,
    role_position,
    sac_config,
    save_resume_state,
    ship_role,
    transfer_source,
    write_plots,
)

SEEDS_FILE = "seeds.json"


def seed_dir(out: Path, seed: int) -> Path:
    return out / f"seed{seed}"


def is_kseed_run(out: Path) -> bool:
    return (out / SEEDS_FILE).is_file()


def train_seeds(cfg: TrainConfig, seeds: tuple[int, ...] | None, out: Path, resume: bool, quiet: bool) -> int:
    """Train ``seeds`` (on --resume: those of ``out/seeds.json``) with ``cfg``, each into ``out/seed<N>``."""
    seeds = check_seeds(cfg, seeds, out, resume)
    cfgs: list[TrainConfig] = []
    scenario: Scenario | None = None
    for seed in seeds:
        seed_cfg, scenario = prepare_run(dataclasses.replace(cfg, seed=seed), seed_dir(out, seed), resume)
        cfgs.append(seed_cfg)
    assert scenario is not None
    first = dataclasses.replace(cfgs[0], seed=0)
    if any(dataclasses.replace(c, seed=0) != first for c in cfgs):
        raise UsageError(f"{out}: the seeds' config.json files differ in more than the seed")
    if not resume:
        write_json(out / SEEDS_FILE, {"seeds": list(seeds)})
    cfg = cfgs[0]
    torch.set_num_threads(cfg.threads)
    outs = [seed_dir(out, seed) for seed in seeds]
    total = len(cfg.roles) * cfg.epochs * cfg.steps_per_epoch
    start = time.perf_counter()
    label = ",".join(str(s) for s in seeds)
    with tqdm(total=total, desc=f"{cfg.algo} seeds {label}", unit="step", disable=quiet, file=sys.stderr, smoothing=0.05) as bar:
        for role_name in cfg.roles:
            if all((o / f"{role_name}.pt").is_file() for o in outs):
                continue
            train_role_kseed(cfgs, scenario, Role(role_name), outs, resume, bar)
            for o in outs:
                write_plots(o, scenario.cost_limit)
    for o in outs:
        write_plots(o, scenario.cost_limit)
    print(f"trained {', '.join(cfg.roles)} with {cfg.algo} (seeds {label}) in {time.perf_counter() - start:.0f} s; results in {out}")
    return 0


def check_seeds(cfg: TrainConfig, seeds: tuple[int, ...] | None, out: Path, resume: bool) -> tuple[int, ...]:
    """The run's seeds; one-line UsageError for a non-SAC algorithm or a mismatch with ``out``."""
    if resume:
        if not is_kseed_run(out):
            raise UsageError(f"--resume: {out / SEEDS_FILE} not found (not a --seeds run)")
        try:
            saved = tuple(int(s) for s in json.loads((out / SEEDS_FILE).read_text())["seeds"])
        except (OSError, ValueError, TypeError, KeyError) as exc:
            raise UsageError(f"--resume: {out / SEEDS_FILE} is not readable ({type(exc).__name__}: {exc})") from None
        if seeds is not None and seeds != saved:
            raise UsageError(f"--seeds {','.join(map(str, seeds))} does not match the run in {out} (seeds {','.join(map(str, saved))})")
        return saved
    if cfg.algo not in SAC_FAMILY:
        raise UsageError(f"--seeds trains the SAC family only ({', '.join(SAC_FAMILY)}), not {cfg.algo}")
    if cfg.stop_at_task_success > 0:
        raise UsageError("--stop-at-task-success ends each seed at its own epoch, and --seeds trains them in lockstep: train the seeds one by one")
    if is_kseed_run(out) or (out / "config.json").is_file():
        raise UsageError(f"{out} already holds a run; use --resume to continue it or choose another --out")
    assert seeds is not None
    return seeds


def train_role_kseed(cfgs: list[TrainConfig], scenario: Scenario, role: Role, outs: list[Path], resume: bool, bar: tqdm) -> None:
    """`train.train_role` for K seeds in lockstep: K `SeedRole`s, one `KSeedSacLagrangian`."""
    cfg = cfgs[0]
    mode = ObservationMode(cfg.observation)
    sac_cfg = sac_config(cfg, scenario)
    # Seed k's learner starts as a single run's would (same torch seed, same construction).
    learner = KSeedSacLagrangian.from_seeds(mode.size, 2, sac_cfg, [c.seed * 1000 + role.index for c in cfgs])
    runs = [open_seed_role(c, scenario, role, o, sac_cfg) for c, o in zip(cfgs, outs)]
    marker = commit_marker(outs[0].parent, role)
    if resume:
        recover_resume_states([r.state_path for r in runs], marker)
    saved = [read_resume_state(r.state_path) for r in runs] if resume else [None] * len(runs)
    if any(s is not None for s in saved):
        epochs = {s["epoch"] if s is not None else 0 for s in saved}
        if len(epochs) != 1:
            raise UsageError(f"{role.value}: the seeds' resume states are at different epochs {sorted(epochs)}")
        for k, (run, state) in enumerate(zip(runs, saved)):
            assert state is not None
            learner.load_seed_state_dict(k, state["learner"])
            learner.generators[k].set_state(state["torch_rng"])
            run.restore(state)
    else:
        sources = [transfer_source(c, role, o) for c, o in zip(cfgs, outs)]
        if sources[0] is not None:
            copied = learner.transfer([learner_state(s) for s in sources if s is not None])
            for run, source in zip(runs, sources):
                assert source is not None
                log_transfer(role, run.cfg, copied, source)
                run.transferred = True
    bar.n = (role_position(cfg, role) * cfg.epochs + runs[0].epoch) * cfg.steps_per_epoch
    bar.refresh()

    def checkpoint_writer(k: int) -> Callable[[Path], None]:
        def write(path: Path) -> None:
            runs[k].write_checkpoint(path, scenario, sac_cfg.hidden_sizes, learner.seed_state_dict(k))

        return write

    writers = [checkpoint_writer(k) for k in range(len(runs))]
    iters = max(1, cfg.steps_per_epoch // cfg.envs)
    for epoch in range(runs[0].epoch + 1, cfg.epochs + 1):
        logs = [EpochLog() for _ in runs]
        for run in runs:
            run.epoch = epoch
        for _ in range(iters):
            t0 = time.perf_counter()
            # All seeds share env_steps and transfer: they explore, or act, together.
            if runs[0].exploring():
                actions = [run.random_action() for run in runs]
            else:
                actions = list(learner.act(np.stack([run.obs for run in runs]), deterministic=False))
            for run, action, log in zip(runs, actions, logs):
                run.collect(action, log)
            t1 = time.perf_counter()
            due = runs[0].updates_due()
            if due is not None:
                for _ in range(due):
                    samples = [run.sample(sac_cfg, learner.uses_multiplier) for run in runs]
                    recents = [recent for _, recent in samples if recent is not None]
                    costs = [run.episode_cost(sac_cfg, learner.uses_multiplier) for run in runs]
                    episode_costs = None if None in costs else costs
                    stats = learner.update([batch for batch, _ in samples], recents or None, episode_costs)
                    for log, s in zip(logs, stats):
                        log.stats.append(s)
                for run in runs:
                    run.updates += max(due, 0)
            t2 = time.perf_counter()
            for log in logs:
                log.env_time += t1 - t0
                if due is not None:
                    log.update_time += t2 - t1
            bar.update(cfg.envs)
        rows = [run.end_epoch(log, iters, write) for run, log, write in zip(runs, logs, writers)]
        bar.set_postfix(role=role.value, ep=epoch, ret=f"{np.mean([r['return'] for r in rows]):.1f}",
                        cost=f"{np.mean([r['cost'] for r in rows]):.1f}")
        save_resume_states(
            [(run.state_path, run.resume_state(learner.seed_state_dict(k), learner.generators[k].get_state())) for k, run in enumerate(runs)],
            marker,
        )
    for run, write in zip(runs, writers):
        ship_role(run.out, role, run.selector, write)


# --- resume states of K seeds, committed together ------------------------------------------------
#
# Each seed's resume state is its own file (seed<N>/resume/<role>.pt, the format of a single run), but
# the K files must describe the same epoch. They are written as <file>.next first; once all are
# written, a marker file says so, the .next files replace the old ones, and the marker goes. A kill
# before the marker leaves the old, consistent set (the .next files are dropped on resume); a kill
# after it leaves complete .next files, which the resume moves into place.


def commit_marker(out: Path, role: Role) -> Path:
    return out / f"resume-{role.value}.commit"


def _pending(path: Path) -> Path:
    return path.with_name(path.name + ".next")


def save_resume_states(states: list[tuple[Path, dict[str, Any]]], marker: Path) -> None:
    for path, state in states:
        save_resume_state(_pending(path), state)
    marker.write_text("\n".join(str(path) for path, _ in states) + "\n")
    recover_resume_states([path for path, _ in states], marker)


def recover_resume_states(paths: list[Path], marker: Path) -> None:
    """Finish an interrupted `save_resume_states`, or drop its incomplete part."""
    committed = marker.is_file()
    for path in paths:
        if _pending(path).is_file():
            if committed:
                _pending(path).replace(path)
            else:
                _pending(path).unlink()
    marker.unlink(missing_ok=True)

"""The experiment grid file (``experiments/*.yaml``): which algorithms and seeds to train, with which
shared training arguments, and how to evaluate the trained teams.

Example (``experiments/paper.yaml`` is the full one)::

    seeds: [0, 1]
    algos:
      - tssac
      - sac_lag
      - {algo: sac_penalty, penalty: -10, name: sac_pen10}
      - {algo: ppo, set: {lr: 1.0e-4}}
      - {preset: configs/safe.yaml, name: tssac_safe}   # a named recipe as a row
    train:
      scenario: scenarios/random.yaml
      epochs: 30
      action_repeat: 10
      sac_set: {hidden_sizes: [128, 128], alpha_init: 0.2}
      onpolicy_set: {hidden_sizes: [128, 128]}
    evaluation:
      scenario: scenarios/random.yaml
      episodes: 50
      seed: 12345
      generalization_scenario: scenarios/generalization.yaml
      tail_episodes: 500           # optional: every team again on 500 more layouts, pooled over seeds with intervals
      tail_seed: 990001
      tail_monitor: true           # and on those layouts through the runtime-assurance monitor (evaluate --shield)
      generalization_tail_episodes: 500   # optional: every team on 500 layouts of generalization_scenario, likewise
      generalization_tail_seed: 991001
    transfer:                      # optional: the transfer experiment (TransferExperiment)
      teammates: models/tssac
      with: tssac
      without: sac_lag
      roles: [detect, strike]
      epochs: 25
      task_success: 0.9

``train:`` is a preset written inline (:mod:`tssac_core.train.preset`: any `TrainConfig` field, e.g.
``steps_per_epoch``, and the learner settings under ``set``, ``sac_set`` for the SAC family and
``onpolicy_set`` for ppo, ppo_lag and cpo), read by the preset reader; ``preset: FILE`` lays it over a preset
file (``configs/paper.yaml``), the section's own keys winning. A row of ``algos`` is a name, an algorithm, or a
mapping that is a preset too (``name``, ``preset: FILE`` and any preset key but ``seed``): laid over ``train:``,
or, with its own ``preset:``, over that file alone, so that ``{preset: configs/safe.yaml, name: safe}`` is
exactly ``python -m tssac_core.train --preset configs/safe.yaml --seed N``. Each job is that row's
`TrainConfig` with a seed of ``seeds`` (`Job.config`); nothing goes through command-line strings. Paths are
relative to the directory the command runs in, as on every other command line. A bad file raises
:class:`GridError`, one line: ``file: field: problem``.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.common.cli import UsageError
from tssac_core.common.options import OptionError
from tssac_core.sim.scenario import ROLES, Role
from tssac_core.sim.scenario import load as load_scenario
from tssac_core.sim.yaml_file import read_yaml, typed_value
from tssac_core.train.algorithms import algorithm
from tssac_core.train.config import TrainConfig, check_learner_settings
from tssac_core.train.jobs.job import AlgoEntry, Job
from tssac_core.train.preset import Preset, load_preset, preset_config, read_settings

NAME_PATTERN = re.compile(r"^[A-Za-z0-9_.-]+$")


class GridError(UsageError):
    """A grid file that cannot be used; ``str()`` is one line: ``file: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        super().__init__(f"{source}: {field_path}: {problem}" if field_path else f"{source}: {problem}")


@dataclass(frozen=True)
class Evaluation:
    """How every finished team is flown: the same layouts for all."""

    scenario: Path
    """Table 4 and figure 10: random layouts (section 5.2.2)."""
    episodes: int = 50
    seed: int = 12345
    """Seed of the evaluation layouts (never a training seed)."""
    generalization_scenario: Path | None = None
    """Figure 11 (section 5.2.3); None: not evaluated."""
    tail_episodes: int | None = None
    """The tail evaluation (issue 23): every team again on this many layouts of ``scenario`` (e.g. 500), enough to
    see a failure that comes once in a hundred missions, reported pooled over seeds with 95% intervals; None: not
    flown."""
    tail_seed: int = 990001
    """Seed of the tail layouts (mission k flies the layout of seed ``tail_seed + k``); its layouts must not be
    the 50 of ``seed``."""
    tail_monitor: bool = False
    """Fly the tail layouts a second time through the runtime-assurance monitor (``evaluate --shield``)."""
    generalization_tail_episodes: int | None = None
    """The generalisation tail: every team also on this many layouts of ``generalization_scenario`` (which it
    needs), drawn and reported as the tail's, without the monitor; None: not flown."""
    generalization_tail_seed: int = 991001
    """Seed of the generalisation tail's layouts (mission k: layout seed ``generalization_tail_seed + k``; the
    default is the tail's + 1,000, as ``tssac_core.experiments.targets`` draws its generalisation layouts); its
    layouts must not be the 50 of ``seed``."""


@dataclass(frozen=True)
class TransferExperiment:
    """The transfer speed-up: learner decisions until a role first reaches ``task_success`` in training, started
    from the previous role's networks (``with_transfer``: TSSAC) or from scratch (``without_transfer``).

    Both sides train the role alone, with the same trained earlier roles flying (``teammates``), for every seed
    of the grid, and stop at the first epoch that reaches the level; so the role's own start is all that
    differs, and neither side's figure depends on how well its own earlier roles happened to learn. The
    grid's training arguments apply, except ``epochs`` (the cap: a role that never gets there counts with all
    its decisions, a lower bound) and ``validation_episodes`` (the figure is read from training).
    """

    teammates: Path
    with_transfer: AlgoEntry
    without_transfer: AlgoEntry
    roles: tuple[str, ...] = ("detect", "strike")
    epochs: int = 25
    task_success: float = 0.9
    validation_episodes: int = 0


@dataclass(frozen=True)
class Grid:
    source: Path
    algos: tuple[AlgoEntry, ...]
    seeds: tuple[int, ...]
    train: TrainConfig
    """The ``train:`` section's configuration (its algorithm: the default), as the rows without a preset start."""
    evaluation: Evaluation
    transfer: TransferExperiment | None = None

    def jobs(self, results: Path) -> list[Job]:
        """Every (entry, seed) run, seed-major: each entry's first seed before any entry's second, so a grid
        stopped part-way (it runs across sessions) has every row of Table 4; directories under ``results/runs``."""
        return [
            Job(e, dataclasses.replace(e.config, seed=s), results / "runs" / f"{e.name}-seed{s}")
            for s in self.seeds
            for e in self.algos
        ]

    def transfer_jobs(self, results: Path) -> list[Job]:
        """The transfer experiment's runs (none without a ``transfer:`` section), seed-major, under ``results/runs``."""
        t = self.transfer
        if t is None:
            return []
        jobs = []
        for s in self.seeds:
            for role in t.roles:
                for e in (t.with_transfer, t.without_transfer):
                    cfg = dataclasses.replace(
                        e.config,
                        seed=s,
                        epochs=t.epochs,
                        validation_episodes=t.validation_episodes,
                        roles=(role,),
                        teammates=str(t.teammates),
                        stop_at_task_success=t.task_success,
                    )
                    jobs.append(Job(e, cfg, Path("unused"), role))
        return [dataclasses.replace(j, out=results / "runs" / j.name) for j in jobs]

    def entry(self, name: str) -> AlgoEntry:
        return next(e for e in self.algos if e.name == name)


def learner_family(algo: str) -> str:
    """``sac`` or ``onpolicy``: the learner an algorithm trains with (its ``--set`` family, ``sac_set`` or
    ``onpolicy_set``)."""
    return algorithm(algo).family.value


# ------------------------------------------------------------------------------------- loading


def load_grid(path: str | Path) -> Grid:
    """Read and check a grid file; every job's training arguments are checked as the command would."""
    source = str(path)
    data = read_yaml(path, GridError)
    r = _Reader(source)
    top = r.mapping(
        data,
        "",
        allowed={"seeds", "algos", "train", "evaluation", "transfer"},
        required={"seeds", "algos", "train", "evaluation"},
    )
    seeds = r.seeds(top["seeds"], "seeds")
    train_layers = r.train_layers(top["train"])
    if not isinstance(top["algos"], list) or not top["algos"]:
        raise GridError(source, "algos", "expected a non-empty list of algorithms")
    algos = tuple(r.algo_entry(item, f"algos[{i}]", train_layers) for i, item in enumerate(top["algos"]))
    names = [e.name for e in algos]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise GridError(source, f"algos[{i}].name", f"{name!r} is used twice (give each entry its own name)")
    ev = r.mapping(
        top["evaluation"], "evaluation", allowed={f.name for f in dataclasses.fields(Evaluation)}, required={"scenario"}
    )
    evaluation = Evaluation(
        scenario=r.scenario(ev["scenario"], "evaluation.scenario"),
        episodes=r.integer(ev.get("episodes", Evaluation.episodes), "evaluation.episodes", minimum=1),
        seed=r.integer(ev.get("seed", Evaluation.seed), "evaluation.seed", minimum=0),
        generalization_scenario=(
            r.scenario(ev["generalization_scenario"], "evaluation.generalization_scenario")
            if ev.get("generalization_scenario") is not None
            else None
        ),
        **r.tail(ev),
        **r.generalization_tail(ev),
    )
    transfer = r.transfer(top["transfer"], {e.name: e for e in algos}) if top.get("transfer") is not None else None
    grid = Grid(Path(path), algos, seeds, r.config(train_layers, "train"), evaluation, transfer)
    check_jobs(grid)
    return grid


def check_jobs(grid: Grid) -> None:
    """Load the scenarios and build every entry's learner config, as the job itself will: a mistake fails now,
    not after hours of training."""
    for path in (grid.evaluation.scenario, grid.evaluation.generalization_scenario):
        if path is not None:
            load_scenario(path)
    for i, entry in enumerate(grid.algos):
        try:
            check_learner_settings(entry.config, load_scenario(entry.config.scenario))
        except UsageError as exc:
            raise GridError(str(grid.source), f"algos[{i}] ({entry.name})", str(exc)) from None


class _Reader:
    """Typed access to plain YAML data; every problem is a GridError naming the field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, problem: str) -> GridError:
        return GridError(self.source, where, problem)

    def mapping(
        self, value: Any, where: str, allowed: Collection[str], required: Collection[str] = ()
    ) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(where, f"expected a mapping, got {type(value).__name__}")
        for key in value:
            if key not in allowed:
                raise self.fail(
                    f"{where}.{key}" if where else str(key), f"unknown key (allowed: {', '.join(sorted(allowed))})"
                )
        for key in sorted(required):
            if key not in value:
                raise self.fail(f"{where}.{key}" if where else key, "missing required field")
        return value

    def integer(self, value: Any, where: str, minimum: int | None = None) -> int:
        value = typed_value(int, value, where, self.source, GridError)
        if minimum is not None and value < minimum:
            raise self.fail(where, f"must be >= {minimum}, got {value}")
        return value

    def number(self, value: Any, where: str) -> float:
        return float(typed_value(float, value, where, self.source, GridError))

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(where, f"expected a non-empty string, got {value!r}")
        return value

    def scenario(self, value: Any, where: str) -> Path:
        """A scenario file as written, relative to the working directory (so that the runs' config.json
        files hold portable paths); it must exist."""
        path = Path(self.string(value, where))
        if not path.is_file():
            raise self.fail(where, f"file not found: {path} (paths are relative to the directory the command runs in)")
        return path

    def seeds(self, value: Any, where: str) -> tuple[int, ...]:
        if not isinstance(value, list) or not value:
            raise self.fail(where, "expected a non-empty list of seeds")
        seeds = tuple(self.integer(v, f"{where}[{i}]", minimum=0) for i, v in enumerate(value))
        if len(set(seeds)) != len(seeds):
            raise self.fail(where, f"a seed is listed twice: {list(seeds)}")
        return seeds

    def settings(self, data: Any, where: str, own: Collection[str]) -> Preset:
        """A section or row that is a preset (``own``: its keys that are not), read by the preset reader."""
        if not isinstance(data, dict):
            raise self.fail(where, f"expected a mapping, got {type(data).__name__}")
        rest = {k: v for k, v in data.items() if k not in own}
        return read_settings(rest, self.source, where, GridError, also=own)

    def config(self, layers: list[Preset], where: str, **fields: Any) -> TrainConfig:
        """The TrainConfig of ``layers`` (`preset_config`); a rule between its fields that fails names the field
        under ``where``."""
        try:
            return preset_config(layers, **fields)
        except OptionError as exc:
            raise self.fail(f"{where}.{exc.field}", exc.problem) from None

    def preset_file(self, data: dict[str, Any], where: str) -> list[Preset]:
        """``preset: FILE`` of a section or row: that file (its error named after this field), or nothing."""
        if "preset" not in data:
            return []
        path = self.string(data["preset"], f"{where}.preset")
        try:
            return [load_preset(path)]
        except UsageError as exc:
            raise self.fail(f"{where}.preset", str(exc)) from None

    def train_layers(self, data: Any) -> list[Preset]:
        """``train:``: its preset file (if any), then its own settings; the scenario must be given and exist."""
        own = self.settings(data, "train", own=("preset",))
        layers = [*self.preset_file(data, "train"), own]
        scenario = self.config(layers, "train").scenario if any("scenario" in p.values for p in layers) else None
        if scenario is None:
            raise self.fail("train.scenario", "missing required field (in the grid file or its preset)")
        where = "train.scenario" if "scenario" in own.values else "train.preset"
        self.scenario(scenario, where)
        return layers

    def tail(self, ev: dict[str, Any]) -> dict[str, Any]:
        """``evaluation.tail_*``: how many layouts of the evaluation scenario, which seed (:meth:`tail_layouts`),
        with the monitor or not."""
        layouts = self.tail_layouts(ev, "tail", also=("tail_monitor",))
        if layouts is None:
            return {}
        monitor = typed_value(
            bool, ev.get("tail_monitor", Evaluation.tail_monitor), "evaluation.tail_monitor", self.source, GridError
        )
        return {**layouts, "tail_monitor": monitor}

    def generalization_tail(self, ev: dict[str, Any]) -> dict[str, Any]:
        """``evaluation.generalization_tail_*``: how many layouts of the generalisation scenario, which seed
        (:meth:`tail_layouts`); the grid must name that scenario."""
        layouts = self.tail_layouts(ev, "generalization_tail")
        if layouts is not None and ev.get("generalization_scenario") is None:
            raise self.fail(
                "evaluation.generalization_tail_episodes",
                "needs evaluation.generalization_scenario (the scenario whose layouts it flies)",
            )
        return layouts or {}

    def tail_layouts(self, ev: dict[str, Any], prefix: str, also: tuple[str, ...] = ()) -> dict[str, int] | None:
        """``evaluation.<prefix>_episodes`` and ``<prefix>_seed`` (its default: `Evaluation`'s), or None if the
        episodes are not given (then neither may the seed nor the keys ``also`` be). Mission k of a seed S flies the
        layout of seed S + k, so the layout seeds must not overlap the 50 of ``evaluation.seed``."""
        episodes_key, seed_key = f"{prefix}_episodes", f"{prefix}_seed"
        if ev.get(episodes_key) is None:
            for key in (seed_key, *also):
                if key in ev:
                    raise self.fail(f"evaluation.{key}", f"needs evaluation.{episodes_key} (how many layouts)")
            return None
        episodes = self.integer(ev[episodes_key], f"evaluation.{episodes_key}", minimum=1)
        seed = self.integer(ev.get(seed_key, getattr(Evaluation, seed_key)), f"evaluation.{seed_key}", minimum=0)
        first = self.integer(ev.get("seed", Evaluation.seed), "evaluation.seed", minimum=0)
        count = self.integer(ev.get("episodes", Evaluation.episodes), "evaluation.episodes", minimum=1)
        if seed < first + count and first < seed + episodes:
            raise self.fail(
                f"evaluation.{seed_key}",
                f"its layout seeds {seed}-{seed + episodes - 1} overlap those of "
                f"evaluation.seed ({first}-{first + count - 1}): the {prefix.replace('_', ' ')} must fly other layouts",
            )
        return {episodes_key: episodes, seed_key: seed}

    def transfer(self, value: Any, entries: dict[str, AlgoEntry]) -> TransferExperiment:
        """``transfer:``: the transfer experiment; its sides name entries of ``algos`` (their settings apply)."""
        where = "transfer"
        data = self.mapping(
            value,
            where,
            allowed={"teammates", "with", "without", "roles", "epochs", "task_success", "validation_episodes"},
            required={"teammates", "with", "without"},
        )
        sides = {}
        for key, must_transfer in (("with", True), ("without", False)):
            name = self.string(data[key], f"{where}.{key}")
            if name not in entries:
                raise self.fail(f"{where}.{key}", f"{name!r} is not an entry of algos ({', '.join(entries)})")
            if algorithm(entries[name].algo).transfers != must_transfer:
                raise self.fail(
                    f"{where}.{key}",
                    f"{name!r} is {entries[name].algo}: 'with' needs tssac (it transfers), 'without' another algorithm",
                )
            sides[key] = entries[name]
        roles = data.get("roles", list(TransferExperiment.roles))
        if (
            not isinstance(roles, list)
            or not roles
            or any(r not in ("detect", "strike") for r in roles)
            or len(set(roles)) != len(roles)
        ):
            raise self.fail(
                f"{where}.roles",
                f"expected a list of detect and/or strike (the roles that have a previous role), got {roles!r}",
            )
        teammates = Path(self.string(data["teammates"], f"{where}.teammates"))
        for role in roles:
            for earlier in ROLES[: Role(role).index]:
                if not (teammates / f"{earlier.value}.pt").is_file():
                    raise self.fail(
                        f"{where}.teammates",
                        f"{teammates / (earlier.value + '.pt')} not found (training {role} needs the trained "
                        f"{earlier.value})",
                    )
        task_success = self.number(data.get("task_success", TransferExperiment.task_success), f"{where}.task_success")
        if not 0.0 < task_success <= 1.0:
            raise self.fail(f"{where}.task_success", f"expected a fraction in (0, 1], got {task_success:g}")
        return TransferExperiment(
            teammates=teammates,
            with_transfer=sides["with"],
            without_transfer=sides["without"],
            roles=tuple(roles),
            epochs=self.integer(data.get("epochs", TransferExperiment.epochs), f"{where}.epochs", minimum=1),
            task_success=task_success,
            validation_episodes=self.integer(
                data.get("validation_episodes", TransferExperiment.validation_episodes),
                f"{where}.validation_episodes",
                minimum=0,
            ),
        )

    def algo_entry(self, item: Any, where: str, train: list[Preset]) -> AlgoEntry:
        """``tssac``, ``{algo: sac_penalty, penalty: -10, name: sac_pen10, set: {...}}`` or
        ``{preset: configs/safe.yaml, name: safe}``: a preset laid over ``train`` (over its own file alone if it
        names one)."""
        data = {"algo": item} if isinstance(item, str) else item
        row = self.settings(data, where, own=("name", "preset"))
        if "seed" in row.values:
            raise self.fail(f"{where}.seed", "a row's seeds are the grid's (seeds:)")
        layers = [*(self.preset_file(data, where) or train), row]
        config = self.config(layers, where, seed=0)
        if "algo" not in data and "preset" not in data:
            raise self.fail(f"{where}.algo", "missing required field")
        name = self.string(data.get("name", str(config.algo)), f"{where}.name")
        if not NAME_PATTERN.match(name):
            raise self.fail(
                f"{where}.name", f"{name!r} may hold only letters, digits, '_', '-' and '.' (it names directories)"
            )
        return AlgoEntry(name=name, config=config)

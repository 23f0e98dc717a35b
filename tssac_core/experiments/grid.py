"""The experiment grid file (``experiments/*.yaml``): which algorithms and seeds to train, with which
shared training arguments, and how to evaluate the trained teams.

Example (``experiments/paper.yaml`` is the full one)::

    seeds: [0, 1]
    algos:
      - tssac
      - sac_lag
      - {algo: sac_penalty, penalty: -10, name: sac_pen10}
      - {algo: ppo, set: {lr: 1.0e-4}}
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
    transfer:                      # optional: the transfer experiment (TransferExperiment)
      teammates: models/tssac
      with: tssac
      without: sac_lag
      roles: [detect, strike]
      epochs: 25
      task_success: 0.9

Every key of ``train`` is an argument of ``python -m tssac_core.train`` (``steps_per_epoch`` is
``--steps-per-epoch``) and is passed to every job alike; a key left out is the command's default.
``preset: FILE`` reads a preset (:mod:`tssac_core.train.preset`, e.g. ``configs/paper.yaml``) whose values the
keys of ``train`` override. ``sac_set`` holds the ``--set`` overrides of the SAC family (tssac, sac_lag, sac,
sac_penalty),
``onpolicy_set`` those of ppo, ppo_lag and cpo (the two learners have different settings), and an
entry's own ``set`` is applied on top for that entry only. Paths are relative to the directory the
command runs in, as on every other command line. A bad file raises :class:`GridError`, one line:
``file: field: problem``.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tssac_core.cli import UsageError
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role
from tssac_core.sim.scenario import load as load_scenario
from tssac_core.sim.yaml_file import read_yaml
from tssac_core.train.algorithms import ALGORITHMS, Selection, algorithm
from tssac_core.train.arguments import parse_args as parse_train_args
from tssac_core.train.config import TrainConfig, check_learner_settings
from tssac_core.train.preset import load_preset

NAME_PATTERN = re.compile(r"^[A-Za-z0-9_.-]+$")


class GridError(UsageError):
    """A grid file that cannot be used; ``str()`` is one line: ``file: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        super().__init__(f"{source}: {field_path}: {problem}" if field_path else f"{source}: {problem}")


@dataclass(frozen=True)
class AlgoEntry:
    """One row of the tables: an algorithm with its own settings."""

    name: str
    """Label in tables and figures, and the prefix of its run directories (default: the algorithm)."""
    algo: str
    """An algorithm of ``tssac_core.train --algo``."""
    penalty: float = 0.0
    """sac_penalty only: reward r + penalty * c."""
    overrides: dict[str, Any] = field(default_factory=dict)
    """This entry's learner settings (``--set``): the family's shared ones, then the entry's own."""


@dataclass(frozen=True)
class TrainArgs:
    """The training arguments every job shares (defaults: those of ``tssac_core.train``)."""

    scenario: Path
    epochs: int = TrainConfig.epochs
    steps_per_epoch: int = TrainConfig.steps_per_epoch
    envs: int = TrainConfig.envs
    action_repeat: int = TrainConfig.action_repeat
    update_every: int = TrainConfig.update_every
    start_steps: int = TrainConfig.start_steps
    update_after: int = TrainConfig.update_after
    threads: int = TrainConfig.threads
    """torch threads of each job (``--jobs`` jobs run at once)."""
    validation_episodes: int = TrainConfig.validation_episodes
    observation: str = TrainConfig.observation
    selection: str = ""
    """"" (default): each algorithm's own epoch selection; a word pins one for every job (TrainConfig.selection)."""


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
class Job:
    """One training run of the grid: a whole team, or one role of the transfer experiment."""

    entry: AlgoEntry
    seed: int
    out: Path
    train_args: tuple[str, ...]
    """Arguments of ``python -m tssac_core.train`` for a new run (without --out)."""
    role: str | None = None
    """The transfer experiment's role (the run trains that role only); None: the whole curriculum."""

    @property
    def name(self) -> str:
        return (
            f"{self.entry.name}-seed{self.seed}"
            if self.role is None
            else f"transfer-{self.role}-{self.entry.name}-seed{self.seed}"
        )

    @property
    def roles(self) -> tuple[str, ...]:
        """The roles this run trains (and whose checkpoints mark it finished)."""
        return self.config().roles if self.role is None else (self.role,)

    def config(self) -> TrainConfig:
        """The TrainConfig this job's run writes to its config.json."""
        cfg, _, _, _ = parse_train_args([*self.train_args, "--out", str(self.out)])
        return cfg


@dataclass(frozen=True)
class Grid:
    source: Path
    algos: tuple[AlgoEntry, ...]
    seeds: tuple[int, ...]
    train: TrainArgs
    evaluation: Evaluation
    transfer: TransferExperiment | None = None

    def jobs(self, results: Path) -> list[Job]:
        """Every (entry, seed) run, seed-major: each entry's first seed before any entry's second, so a grid
        stopped part-way (it runs across sessions) has every row of Table 4; directories under ``results/runs``."""
        return [
            Job(e, s, results / "runs" / f"{e.name}-seed{s}", train_argv(self.train, e, s))
            for s in self.seeds
            for e in self.algos
        ]

    def transfer_jobs(self, results: Path) -> list[Job]:
        """The transfer experiment's runs (none without a ``transfer:`` section), seed-major, under ``results/runs``."""
        t = self.transfer
        if t is None:
            return []
        args = dataclasses.replace(self.train, epochs=t.epochs, validation_episodes=t.validation_episodes)
        jobs = []
        for s in self.seeds:
            for role in t.roles:
                for e in (t.with_transfer, t.without_transfer):
                    argv = (
                        *train_argv(args, e, s),
                        "--roles",
                        role,
                        "--teammates",
                        str(t.teammates),
                        "--stop-at-task-success",
                        repr(t.task_success),
                    )
                    jobs.append(Job(e, s, Path("unused"), argv, role))
        return [dataclasses.replace(j, out=results / "runs" / j.name) for j in jobs]

    def entry(self, name: str) -> AlgoEntry:
        return next(e for e in self.algos if e.name == name)


def learner_family(algo: str) -> str:
    """``sac`` or ``onpolicy``: the learner an algorithm trains with (its ``--set`` family, ``sac_set`` or
    ``onpolicy_set``)."""
    return algorithm(algo).family.value


def train_argv(args: TrainArgs, entry: AlgoEntry, seed: int) -> tuple[str, ...]:
    """The ``tssac_core.train`` arguments of one run."""
    argv = [
        "--algo",
        entry.algo,
        "--seed",
        str(seed),
        "--scenario",
        str(args.scenario),
        "--epochs",
        str(args.epochs),
        "--steps-per-epoch",
        str(args.steps_per_epoch),
        "--envs",
        str(args.envs),
        "--action-repeat",
        str(args.action_repeat),
        "--update-every",
        str(args.update_every),
        "--start-steps",
        str(args.start_steps),
        "--update-after",
        str(args.update_after),
        "--threads",
        str(args.threads),
        "--validation-episodes",
        str(args.validation_episodes),
        "--observation",
        args.observation,
    ]
    if args.selection:
        argv += ["--selection", args.selection]
    if entry.algo == "sac_penalty":
        argv += ["--penalty", repr(entry.penalty)]
    for key, value in entry.overrides.items():
        argv += ["--set", f"{key}={json.dumps(value, separators=(',', ':'))}"]
    return tuple(argv)


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
    train_fields = {f.name for f in dataclasses.fields(TrainArgs)}
    train_data = r.mapping(top["train"], "train", allowed=train_fields | {"sac_set", "onpolicy_set", "preset"})
    preset = load_preset(r.string(train_data["preset"], "train.preset")) if "preset" in train_data else None
    family_sets = {
        "sac": r.overrides(train_data.get("sac_set", {}), "train.sac_set"),
        "onpolicy": r.overrides(train_data.get("onpolicy_set", {}), "train.onpolicy_set"),
    }
    if preset is not None:  # the preset's values first, the grid file's own on top
        outside = sorted(set(preset.values) - train_fields)
        if outside:
            raise GridError(
                source,
                "train.preset",
                f"{preset.source}: {', '.join(outside)}: not a grid training argument "
                f"(the grid's are {', '.join(sorted(train_fields))})",
            )
        train_data = {**preset.values, **{k: v for k, v in train_data.items() if k != "preset"}}
        family_sets = {
            family: {**preset.learner_settings(example), **family_sets[family]}
            for family, example in (("sac", "tssac"), ("onpolicy", "ppo"))
        }
    if "scenario" not in train_data:
        raise GridError(source, "train.scenario", "missing required field (in the grid file or its preset)")
    train = r.train_args(train_data)
    if not isinstance(top["algos"], list) or not top["algos"]:
        raise GridError(source, "algos", "expected a non-empty list of algorithms")
    algos = tuple(r.algo_entry(item, f"algos[{i}]", family_sets) for i, item in enumerate(top["algos"]))
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
    )
    transfer = r.transfer(top["transfer"], {e.name: e for e in algos}) if top.get("transfer") is not None else None
    grid = Grid(Path(path), algos, seeds, train, evaluation, transfer)
    check_jobs(grid)
    return grid


def check_jobs(grid: Grid) -> None:
    """Load the scenarios, parse every entry's training command and build its learner config, as the job
    itself will: a mistake fails now, not after hours of training."""
    for path in (grid.evaluation.scenario, grid.evaluation.generalization_scenario):
        if path is not None:
            load_scenario(path)
    scenario = load_scenario(grid.train.scenario)
    for i, entry in enumerate(grid.algos):
        job = Job(entry, grid.seeds[0], Path("unused"), train_argv(grid.train, entry, grid.seeds[0]))
        try:
            check_learner_settings(job.config(), scenario)
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
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(where, f"expected an integer, got {value!r}")
        if minimum is not None and value < minimum:
            raise self.fail(where, f"must be >= {minimum}, got {value}")
        return value

    def number(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"expected a number, got {value!r}")
        return float(value)

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

    def overrides(self, value: Any, where: str) -> dict[str, Any]:
        """Learner settings: names to numbers, booleans, words or lists of numbers (what ``--set`` takes)."""
        if not isinstance(value, dict):
            raise self.fail(where, f"expected a mapping of learner settings, got {type(value).__name__}")
        for key, v in value.items():
            ok = (
                isinstance(v, (int, float, bool, str))
                or v is None
                or (isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v))
            )
            if not isinstance(key, str) or not ok:
                raise self.fail(
                    f"{where}.{key}", f"expected a number, boolean, word, null or list of numbers, got {v!r}"
                )
        return dict(value)

    def train_args(self, data: dict[str, Any]) -> TrainArgs:
        """``train:`` without the learner settings; counts as ``tssac_core.train`` accepts them."""
        values: dict[str, Any] = {"scenario": self.scenario(data["scenario"], "train.scenario")}
        for key, minimum in (
            ("epochs", 1),
            ("steps_per_epoch", 1),
            ("envs", 1),
            ("action_repeat", 1),
            ("update_every", 1),
            ("threads", 1),
            ("start_steps", 0),
            ("update_after", 0),
            ("validation_episodes", 0),
        ):
            if key in data:
                values[key] = self.integer(data[key], f"train.{key}", minimum)
        if "observation" in data:
            modes = [m.value for m in ObservationMode]
            if data["observation"] not in modes:
                raise self.fail("train.observation", f"expected one of {', '.join(modes)}, got {data['observation']!r}")
            values["observation"] = data["observation"]
        if "selection" in data:
            if data["selection"] not in list(Selection):
                raise self.fail("train.selection", f"expected one of {', '.join(Selection)}, got {data['selection']!r}")
            values["selection"] = data["selection"]
        return TrainArgs(**values)

    def tail(self, ev: dict[str, Any]) -> dict[str, Any]:
        """``evaluation.tail_*``: how many layouts, which seed, with the monitor or not. Mission k of a seed S flies
        the layout of seed S + k, so the tail's layout seeds must not overlap the 50 of ``evaluation.seed``."""
        if ev.get("tail_episodes") is None:
            for key in ("tail_seed", "tail_monitor"):
                if key in ev:
                    raise self.fail(f"evaluation.{key}", "needs evaluation.tail_episodes (how many layouts)")
            return {}
        episodes = self.integer(ev["tail_episodes"], "evaluation.tail_episodes", minimum=1)
        seed = self.integer(ev.get("tail_seed", Evaluation.tail_seed), "evaluation.tail_seed", minimum=0)
        monitor = ev.get("tail_monitor", Evaluation.tail_monitor)
        if not isinstance(monitor, bool):
            raise self.fail("evaluation.tail_monitor", f"expected true or false, got {monitor!r}")
        first = self.integer(ev.get("seed", Evaluation.seed), "evaluation.seed", minimum=0)
        count = self.integer(ev.get("episodes", Evaluation.episodes), "evaluation.episodes", minimum=1)
        if seed < first + count and first < seed + episodes:
            raise self.fail(
                "evaluation.tail_seed",
                f"its layout seeds {seed}-{seed + episodes - 1} overlap those of "
                f"evaluation.seed ({first}-{first + count - 1}): the tail must fly other layouts",
            )
        return {"tail_episodes": episodes, "tail_seed": seed, "tail_monitor": monitor}

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

    def algo_entry(self, item: Any, where: str, family_sets: dict[str, dict[str, Any]]) -> AlgoEntry:
        """``tssac`` or ``{algo: sac_penalty, penalty: -10, name: sac_pen10, set: {...}}``."""
        data = (
            {"algo": item}
            if isinstance(item, str)
            else self.mapping(item, where, allowed={"algo", "name", "penalty", "set"}, required={"algo"})
        )
        algo = self.string(data["algo"], f"{where}.algo")
        if algo not in ALGORITHMS:
            raise self.fail(f"{where}.algo", f"unknown algorithm {algo!r} (choose from {', '.join(ALGORITHMS)})")
        name = self.string(data.get("name", algo), f"{where}.name")
        if not NAME_PATTERN.match(name):
            raise self.fail(
                f"{where}.name", f"{name!r} may hold only letters, digits, '_', '-' and '.' (it names directories)"
            )
        penalty = self.number(data.get("penalty", 0.0), f"{where}.penalty")
        if penalty != 0.0 and algo != "sac_penalty":
            raise self.fail(f"{where}.penalty", f"only sac_penalty takes a penalty, not {algo}")
        family = family_sets[learner_family(algo)]
        overrides = {**family, **self.overrides(data.get("set", {}), f"{where}.set")}
        return AlgoEntry(name=name, algo=algo, penalty=penalty, overrides=overrides)

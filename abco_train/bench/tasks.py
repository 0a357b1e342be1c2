"""Benchmark tracks: named tasks, each an (environment, setting) pair with an interaction budget.

A track is a TOML file (the built-in ones live in ``abco_train/bench/tracks/``; ``abco bench
--track headline`` or ``--track my_track.toml``)::

    [track]
    name = "headline"
    description = "..."
    methods = ["random", "expert", "bc", "bco", "abco"]
    validation_seeds = "100-102"    # choices are made on these
    test_seeds = "1000-1009"        # run once, after the choices are frozen

    [[task]]
    name = "cartpole-authors-data"
    env = "CartPole-v1"
    budget = 20000                  # environment interactions of a run, all kinds summed
    test_seeds = "1000-1004"        # optional: the task's own, instead of the track's
    headline = "episodes"           # the final-evaluation block the task ranks by
    measures = "what the task measures"
    basis = "the paper's or peer's setting that justifies it"
    settings = { pre_transitions = 10000 }   # run-config fields (abco train's options)
    [task.method_settings.bco]      # run-config fields of one method on this task (optional)
    lr = 0.001
    [task.method_options.gaifo]     # options of one method on this task (optional)
    ppo_epochs = 10

A cell of a track's grid is ``(task, method, seed)``; its run folder is
``OUT/{task}/{method}/seed{seed}`` and its config the task's settings (and the method's
``method_settings`` on top) with ``env``, ``task``, ``budget`` and ``headline`` set, so
every record says which task and budget it ran under.

Example:
    >>> track = load_track("headline")
    >>> len(track.tasks) >= 7, track.test_seeds
    (True, '2000-2019')
    >>> task = track.task(track.tasks[0].name)
    >>> task.config()["budget"] == task.budget
    True
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from abco_train.bench.ranges import parse_seeds
from abco_train.bench.records import RecordError, check_name, escape
from abco_train.config.fields import ConfigError
from abco_train.config.limits import MAX_BUDGET
from abco_train.config.run import env_kind, validation_block

__all__ = ["Task", "Track", "load_track", "budget_variants", "TRACKS_DIR", "BUILTIN_TRACKS",
           "MAX_TASKS", "MAX_TRACK_BYTES", "MAX_MULTIPLE"]  # fmt: skip

#: Where the built-in tracks live.
TRACKS_DIR = Path(__file__).with_name("tracks")
#: The built-in tracks (``--track NAME``).
BUILTIN_TRACKS = ("headline",)
#: Most tasks of a track, and most bytes of a track file (read before parsing).
MAX_TASKS = 1_000
MAX_TRACK_BYTES = 1_000_000
#: Largest budget multiple of a budget curve's variant.
MAX_MULTIPLE = 64
#: Run-config fields a task may not set: the grid sets them per cell.
_PER_CELL = ("env", "method", "seed", "run_dir", "quiet", "threads", "task", "budget",
             "headline", "held_out", "method_options")  # fmt: skip
_TRACK_KEYS = {"name", "description", "methods", "validation_seeds", "test_seeds"}
_TASK_KEYS = {"name", "env", "budget", "headline", "measures", "basis", "settings",
              "method_settings", "method_options", "test_seeds"}  # fmt: skip


@dataclass(frozen=True)
class Task:
    """One task of a track: an environment, its settings and its budget.

    Attributes:
        name: The task's name (its folder under the grid's).
        env: The environment id.
        budget: Environment interactions a run may spend, all kinds summed.
        headline: The final-evaluation block the task ranks by (``None``: the default).
        measures: What the task measures.
        basis: The paper's or peer's setting its difficulty comes from.
        settings: Run-config fields of every run of the task.
        method_settings: Run-config fields of single methods' runs (on top of ``settings``),
            by method name: e.g. a learning rate chosen for one method.
        method_options: Options of single methods on this task, by method name.
        test_seeds: The task's own test seeds, instead of the track's (``""``: the track's):
            fewer where a task's runs cost more, more where its scores spread wider.
    """

    name: str
    env: str
    budget: int
    headline: str | None = None
    measures: str = ""
    basis: str = ""
    settings: Mapping[str, Any] = field(default_factory=dict)
    method_settings: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    method_options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    test_seeds: str = ""

    def config(self, method: str | None = None, validation: bool = False) -> dict[str, Any]:
        """The run-config fields of a run of this task (``method``'s options included);
        ``validation``: a run on the track's validation seeds, whose mazes play validation
        layouts (``held_out``) and rank by the block standing for the headline's."""
        options = dict(self.method_options.get(method, {})) if method else {}
        own = dict(self.method_settings.get(method, {})) if method else {}
        headline, validation = self.headline, validation and env_kind(self.env) == "maze"
        if validation and headline:
            headline = validation_block(headline)
        return {**self.settings, **own, "env": self.env, "task": self.name, "budget": self.budget,
                **({"headline": headline} if headline else {}),
                **({"held_out": "validation"} if validation else {}),
                **({"method_options": options} if options else {})}  # fmt: skip


@dataclass(frozen=True)
class Track:
    """A named set of tasks with its methods and seeds (see the module docstring)."""

    name: str
    tasks: tuple[Task, ...]
    description: str = ""
    methods: tuple[str, ...] = ()
    validation_seeds: str = ""
    test_seeds: str = ""
    #: The track whose tuning this one takes (``""``: its own); a budget curve's track,
    #: which only varies budgets, takes the track it varies (:func:`budget_variants`).
    tuned_as: str = ""

    @property
    def tuning_name(self) -> str:
        """The name an ``abco tune`` record of this track's settings carries."""
        return self.tuned_as or self.name

    def task(self, name: str) -> Task:
        """The task called ``name``.

        Raises:
            ConfigError: No such task (the message lists the track's).
        """
        for task in self.tasks:
            if task.name == name:
                return task
        raise ConfigError(f"track {self.name!r} has no task {escape(name, 60)!r}; its tasks: "
                          f"{', '.join(t.name for t in self.tasks)}")  # fmt: skip

    def own_test_seeds(self) -> dict[str, list[int]]:
        """``task -> its test seeds``, for the tasks whose own differ from the track's."""
        return {t.name: parse_seeds(t.test_seeds) for t in self.tasks if t.test_seeds}

    def grid_seeds(self, given: str) -> tuple[list[int], dict[str, list[int]]]:
        """The seeds of ``abco bench --seeds given``: ``validation`` or ``test`` (the track's,
        and each task's own test seeds by task), or seeds written out.

        Raises:
            ConfigError: Bad seeds, or a name the track gives no seeds for.
        """
        if given not in ("validation", "test"):
            return parse_seeds(given), {}
        text = self.validation_seeds if given == "validation" else self.test_seeds
        own = self.own_test_seeds() if given == "test" else {}
        if not text and len(own) < len(self.tasks):  # some task would have no seeds
            raise ConfigError(f"track {self.name} names no {given} seeds; give them")
        return (parse_seeds(text) if text else []), own

    def why_not_validation(self, seed: int) -> str | None:
        """Why ``seed`` may not serve a choice or a measurement (``None``: it is one of the
        track's validation seeds): ``"a test seed"`` or ``"not a validation seed"``.

        Example:
            >>> track = load_track("headline")
            >>> track.why_not_validation(100), track.why_not_validation(2000)
            (None, 'a test seed')
        """
        if self.validation_seeds and seed in parse_seeds(self.validation_seeds):
            return None
        return "a test seed" if seed in self.all_test_seeds() else "not a validation seed"

    def all_test_seeds(self) -> list[int]:
        """Every seed some task is tested on: the track's and the tasks' own."""
        seeds = set(parse_seeds(self.test_seeds)) if self.test_seeds else set()
        return sorted(seeds.union(*self.own_test_seeds().values()))


def load_track(name_or_path: str | os.PathLike[str]) -> Track:
    """A built-in track by name, or a track file.

    Raises:
        ConfigError: No such track or file, a file too large, not TOML, or a track that does
            not fit the format (unknown keys, bad names, settings no run config takes).
    """
    from abco_train.harness.run_folder import RunFolderError, read_capped

    text = str(name_or_path)
    path = TRACKS_DIR / f"{text}.toml" if text in BUILTIN_TRACKS else Path(text)
    try:
        if path.is_file() and path.stat().st_size > MAX_TRACK_BYTES:
            raise ConfigError(f"--track {escape(text, 80)} is larger than "
                              f"{MAX_TRACK_BYTES:,} bytes: no track file")  # fmt: skip
        raw = read_capped(path, MAX_TRACK_BYTES)
    except RunFolderError as exc:
        raise ConfigError(f"--track {escape(text, 80)}: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"--track {escape(text, 80)}: cannot read it ({exc.strerror}); "
                          f"built-in tracks: {', '.join(BUILTIN_TRACKS)}") from None
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10: the same parser, from PyPI
        import tomli as tomllib  # pyright: ignore[reportMissingImports]
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"--track {escape(text, 80)} is not a TOML file: "
                          f"{escape(exc, 120)}") from None
    try:
        return _track(data)
    except (RecordError, ConfigError, TypeError, ValueError) as exc:
        raise ConfigError(f"--track {escape(text, 80)}: {escape(exc, 300)}") from None


def _known(table: Any, keys: set[str], what: str) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise ValueError(f"{what} is not a table")
    unknown = sorted(set(table) - keys)
    if unknown:
        raise ValueError(f"{what} has unknown key(s) {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(sorted(keys))}")  # fmt: skip
    return table


def _text(value: Any, what: str, limit: int = 2_000) -> str:
    if not isinstance(value, str) or len(value) > limit:
        raise ValueError(f"{what} is not text of at most {limit:,} characters")
    return value


def _track(data: Any) -> Track:
    head = _known(data.get("track", {}) if isinstance(data, dict) else None, _TRACK_KEYS,
                  "[track]")  # fmt: skip
    _known(data, {"track", "task"}, "the file")
    tasks = data.get("task", [])
    if not isinstance(tasks, list) or not 0 < len(tasks) <= MAX_TASKS:
        raise ValueError(f"a track holds 1 to {MAX_TASKS:,} [[task]] tables")
    methods = head.get("methods", [])
    if not isinstance(methods, list) or len(methods) > MAX_TASKS:
        raise ValueError("[track] methods is not a list of names")
    built = tuple(_task(t, i) for i, t in enumerate(tasks))
    names = [t.name for t in built]
    if len(set(names)) != len(names):
        raise ValueError("two tasks have one name")
    for task in built:  # a misspelt method would quietly run the defaults
        strays = sorted((set(task.method_settings) | set(task.method_options)) - set(methods))
        if methods and strays:
            raise ValueError(f"task {task.name!r} sets options of {', '.join(strays)}, not a "
                             f"method of the track ({', '.join(methods)})")  # fmt: skip
    track = Track(
        name=check_name(head.get("name", "track"), "track name"), tasks=built,
        description=_text(head.get("description", ""), "[track] description", 20_000),
        methods=tuple(check_name(m, "method name") for m in methods),
        validation_seeds=_text(head.get("validation_seeds", ""), "validation_seeds", 200),
        test_seeds=_text(head.get("test_seeds", ""), "test_seeds", 200),
    )  # fmt: skip
    _check_apart(track)
    return track


def _check_apart(track: Track) -> None:
    """No seed is both a validation seed (choices are made on it) and a test seed."""
    validation = set(parse_seeds(track.validation_seeds)) if track.validation_seeds else set()
    both = sorted(validation & set(track.all_test_seeds()))
    if both:
        raise ValueError(f"seed(s) {', '.join(map(str, both[:5]))} are both validation and "
                         "test seeds; choices made on a seed cannot be tested on it")


def _task(table: Any, index: int) -> Task:
    from abco_train.config.run import RunConfig

    where = f"task {index + 1}"
    t = _known(table, _TASK_KEYS, where)
    name = check_name(t.get("name"), f"{where}'s name")
    settings_keys = set(RunConfig.__dataclass_fields__) - set(_PER_CELL)
    settings = _known(t.get("settings", {}), settings_keys, f"task {name!r} settings")
    budget = t.get("budget")
    if isinstance(budget, bool) or not isinstance(budget, int) or not 0 < budget <= MAX_BUDGET:
        raise ValueError(f"task {name!r} needs a budget from 1 to {MAX_BUDGET:,}")
    options = t.get("method_options", {})
    if not isinstance(options, dict) or not all(isinstance(v, dict) for v in options.values()):
        raise ValueError(f"task {name!r} method_options is not a table of tables")
    per_method = t.get("method_settings", {})
    if not isinstance(per_method, dict):
        raise ValueError(f"task {name!r} method_settings is not a table of tables")
    per_method = {check_name(m, "method name"): _known(v, settings_keys, f"task {name!r} "
                  f"method_settings.{m}") for m, v in per_method.items()}  # fmt: skip
    headline, test_seeds = t.get("headline"), _text(t.get("test_seeds", ""), "test_seeds", 200)
    if test_seeds:  # checked where the track is read, not when its grid runs
        try:
            parse_seeds(test_seeds)
        except ConfigError as exc:
            raise ValueError(f"task {name!r} test_seeds: {exc}") from None
    task = Task(name=name, env=_text(t.get("env"), f"task {name!r} env", 200), budget=budget,
                headline=None if headline is None else _text(headline, "headline", 100),
                measures=_text(t.get("measures", ""), "measures"),
                basis=_text(t.get("basis", ""), "basis"), settings=dict(settings),
                method_settings={m: dict(v) for m, v in per_method.items()},
                method_options={check_name(m, "method name"): dict(o)
                                for m, o in options.items()}, test_seeds=test_seeds)  # fmt: skip
    RunConfig(**task.config()).validate()  # the env, the settings' types and bounds, headline
    for method in task.method_settings:
        RunConfig(**{**task.config(method), "method_options": {}}).validate()
    return task


def budget_variants(track: Track, multiples: Sequence[int | str],
                    tasks: Sequence[str] | None = None) -> Track:  # fmt: skip
    """``track`` with each task (of ``tasks``, or all) replaced by its budget variants
    ``{task}@x{M}``: the task unchanged but for its budget, ``M`` times as large, and any
    method option set to the task's budget (GAIfO's ``rl_steps``: its PPO may spend the whole
    budget), which follows it. ``multiples`` may be text (``abco bench --budget-multiples``).

    These are the points of a budget curve; the 1x point is the task itself.

    Example:
        >>> curves = budget_variants(load_track("headline"), [4, 16])
        >>> task = curves.task("lunarlander@x16")
        >>> task.budget, task.method_options["gaifo"]["rl_steps"]
        (640000, 640000)
        >>> curves.name, curves.tuning_name  # the headline's tuned settings apply
        ('headline-budget-curves', 'headline')

    Raises:
        ConfigError: No multiple, one that is not a whole number from 2 to ``MAX_MULTIPLE``,
            an unknown task, or a budget over the largest a run may have.
    """
    if not multiples:
        raise ConfigError("--budget-multiples names no multiple")
    whole = []
    for text in multiples:
        try:
            whole.append(int(text))
        except ValueError:
            raise ConfigError(f"--budget-multiples: {str(text)[:20]!r} is not a whole number"
                              ) from None  # fmt: skip
        if not 2 <= whole[-1] <= MAX_MULTIPLE:
            raise ConfigError(f"--budget-multiples: {whole[-1]} is not a multiple from 2 to "
                              f"{MAX_MULTIPLE}")  # fmt: skip
    chosen = [track.task(name) for name in tasks] if tasks else list(track.tasks)
    variants = []
    for task in chosen:
        for multiple in whole:
            budget = task.budget * multiple
            if budget > MAX_BUDGET:
                raise ConfigError(f"task {task.name!r} at {multiple}x its budget would have "
                                  f"{budget:,} interactions; a run has at most {MAX_BUDGET:,}")
            options = {m: {k: budget if v == task.budget else v for k, v in o.items()}
                       for m, o in task.method_options.items()}  # fmt: skip
            variants.append(dataclasses.replace(
                task, name=f"{task.name}@x{multiple}", budget=budget, method_options=options,
                measures=f"The task {task.name} with {multiple} times its budget."))
    if len(variants) > MAX_TASKS:
        raise ConfigError(f"{len(variants):,} budget variants; a track has at most "
                          f"{MAX_TASKS:,}")  # fmt: skip
    return dataclasses.replace(track, name=f"{track.name}-budget-curves",
                               tasks=tuple(variants), tuned_as=track.tuning_name)  # fmt: skip

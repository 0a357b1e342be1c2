"""The cells of an ``abco bench`` grid: what one cell is, the command line's lists, the plan.

A cell is one (env, method, seed) training run, or (env, method, layouts K, seed) in a grid
over numbers of training layouts; its run folder is ``OUT/{env}/{method}/seed{seed}`` or
``OUT/{env}/{method}/layouts{K}/seed{seed}`` (:meth:`Cell.run_dir`), and its path under
``OUT`` is its key in ``results.jsonl`` (:mod:`abco_train.bench.results_log`). The grid runner
is :mod:`abco_train.bench.grid`.

Every list of the command line is bounded before anything is built from it: seeds are ASCII
digits up to :data:`~abco_train.config.limits.MAX_SEED`, at most :data:`MAX_CELLS` of them;
``--layouts`` values from 1 to :data:`~abco_train.config.run.MAX_LAYOUTS`; a plan holds at most
:data:`MAX_CELLS` cells, and an empty ``--envs`` or ``--methods`` is no plan.

Example:
    >>> parse_seeds("0-2,7")
    [0, 1, 2, 7]
    >>> [c.key for c in plan(["CartPole-v1"], ["bc", "abco"], [0])]
    ['CartPole-v1/bc/seed0', 'CartPole-v1/abco/seed0']
    >>> [c.key for c in plan(["AbcoMaze5x5-v0"], ["bc"], [0], layouts=[100, 1000])]
    ['AbcoMaze5x5-v0/bc/layouts100/seed0', 'AbcoMaze5x5-v0/bc/layouts1000/seed0']
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from abco_train.bench.ranges import MAX_CELLS, parse_layouts, parse_seeds
from abco_train.bench.records import RecordError, check_name
from abco_train.bench.tasks import Track
from abco_train.config.run import ConfigError, RunConfig, env_kind
from abco_train.methods.registry import options_class, scoped_options

__all__ = ["Cell", "CELL_FIELDS", "MAX_CELLS", "parse_seeds", "parse_list", "parse_layouts",
           "plan", "plan_track", "cell_config", "check_method_options", "Tuned"]  # fmt: skip

#: Config fields the grid sets per cell (never trainer overrides).
CELL_FIELDS = ("env", "method", "seed", "layouts", "run_dir", "quiet", "threads",
               "method_options")  # fmt: skip
#: Settings chosen per ``(method, task family)``: ``(run settings, method options)``.
Tuned = Mapping[tuple[str, str], tuple[Mapping[str, Any], Mapping[str, Any]]]


@dataclass(frozen=True)
class Cell:
    """One training run of the grid."""

    env: str
    method: str
    seed: int
    layouts: int | None = None
    #: The track's task of the cell (:mod:`abco_train.bench.tasks`), else ``None``.
    task: str | None = None

    @property
    def key(self) -> str:
        """``env/method/seed{seed}`` (``env/method/layouts{K}/seed{seed}`` for a cell that
        trains on the first K procedural layouts; ``task/method/seed{seed}`` for a track's):
        its run folder under the grid's folder."""
        return str(self.run_dir(Path())).replace(os.sep, "/")

    @property
    def ident(self) -> tuple[str, str, int, int | None]:
        """``(task or env, method, seed, layouts)``: what its record must say it is."""
        return self.task or self.env, self.method, self.seed, self.layouts

    def run_dir(self, out: str | os.PathLike[str]) -> Path:
        """The cell's run folder under ``out``."""
        folder = Path(out) / (self.task or self.env) / self.method
        if self.layouts is not None and self.task is None:  # a task's layouts are its setting
            folder = folder / f"layouts{self.layouts}"
        return folder / f"seed{self.seed}"


def parse_list(text: str) -> list[str]:
    """Comma-separated names, blanks dropped, order kept, no repeats."""
    return list(dict.fromkeys(name for name in (p.strip() for p in text.split(",")) if name))


def plan(envs: Sequence[str], methods: Sequence[str], seeds: Sequence[int],
         layouts: Sequence[int | None] = (None,)) -> list[Cell]:  # fmt: skip
    """Every (env, method, layouts, seed) cell, env-major; ``layouts``: numbers of training
    layouts (``None``: the standard datasets).

    Raises:
        ConfigError: No env, method, seed or layouts; a name that cannot be a folder's; more
            than :data:`MAX_CELLS` cells (checked before any cell is made).
    """
    for given, what in ((envs, "--envs"), (methods, "--methods"), (seeds, "--seeds"),
                        (layouts, "--layouts")):  # fmt: skip
        if not given:
            raise ConfigError(f"no {what} given: the grid would have no cell")
    for names, what in ((envs, "--envs"), (methods, "--methods")):
        for name in names:
            try:
                check_name(name, what[2:-1])
            except RecordError as exc:
                raise ConfigError(f"{what}: {exc}") from None
    n = len(envs) * len(methods) * len(seeds) * len(layouts)
    if n > MAX_CELLS:
        raise ConfigError(f"{n:,} cells ({len(envs)} envs x {len(methods)} methods x"
                          f" {len(seeds)} seeds x {len(layouts)} layouts); a grid holds at"
                          f" most {MAX_CELLS:,}")  # fmt: skip
    return [Cell(e, m, int(s), None if k is None else int(k))
            for e in envs for m in methods for k in layouts for s in seeds]  # fmt: skip


def plan_track(track: Track, tasks: Sequence[str], methods: Sequence[str],
               seeds: Sequence[int], own: Mapping[str, Sequence[int]] | None = None
               ) -> list[Cell]:  # fmt: skip
    """Every (task, method, seed) cell of ``track``, task-major (``tasks``: all when empty);
    a task named in ``own`` runs its seeds there instead of ``seeds`` (its own test seeds:
    :meth:`~abco_train.bench.tasks.Track.own_test_seeds`).

    Raises:
        ConfigError: An unknown task, no method or seed, a bad name, too many cells.
    """
    chosen = [track.task(name) for name in tasks] if tasks else list(track.tasks)
    if not methods:
        raise ConfigError("no --methods given: the grid would have no cell")
    for name in methods:
        try:
            check_name(name, "method")
        except RecordError as exc:
            raise ConfigError(f"--methods: {exc}") from None
    seeds_of = {t.name: list((own or {}).get(t.name, seeds)) for t in chosen}
    if not all(seeds_of.values()):
        raise ConfigError("no --seeds given: the grid would have no cell")
    n = len(methods) * sum(len(s) for s in seeds_of.values())
    if n > MAX_CELLS:
        raise ConfigError(f"{n:,} cells; a grid holds at most {MAX_CELLS:,}")
    return [Cell(t.env, m, int(s), t.settings.get("layouts"), t.name)
            for t in chosen for m in methods for s in seeds_of[t.name]]  # fmt: skip


def cell_config(
    cell: Cell,
    out: str | os.PathLike[str],
    overrides: dict[str, Any] | None = None,
    threads: int = 1,
    method_options: dict[str, Any] | None = None,
    track: Track | None = None,
    tuned: Tuned | None = None,
) -> dict[str, Any]:
    """The keyword arguments of the cell's :class:`abco_train.config.run.RunConfig`.

    Args:
        cell: The cell.
        out: The grid's folder.
        overrides: Trainer settings applied to every cell (``None`` values are dropped); a
            method's option given here (``idm_epochs``) counts as one of ``method_options``.
        threads: Torch threads of the cell.
        method_options: Method options for every cell whose method has them (a grid of
            several methods gives each its own; :func:`check_method_options` refuses an
            option that no method of the grid has).
        track: The track of a task's cell: the task's settings, budget, headline and its
            options for the cell's method come first; on the track's validation seeds, a
            maze's final evaluation plays validation layouts (``held_out``), never the test's.
        tuned: Settings chosen per method and task family (``abco tune``'s ``choices.json``):
            the cell's, under ``overrides`` and ``method_options`` (which win).

    Raises:
        ConfigError: An override of a per-cell field (env, method, seed, run_dir, ...), or of
            what the cell's task fixes (its budget, headline or a setting).
    """
    settings, chosen = (tuned or {}).get((cell.method, env_kind(cell.env)), ({}, {}))
    overrides = {**settings, **{k: v for k, v in (overrides or {}).items() if v is not None}}
    method_options = {**chosen, **(method_options or {})}
    clash = sorted(set(overrides) & set(CELL_FIELDS))
    if clash:
        raise ConfigError(f"the grid sets {', '.join(clash)} per cell; not an override")
    task = {}
    if track is not None and cell.task:
        validation = bool(track.validation_seeds) and cell.seed in parse_seeds(
            track.validation_seeds)  # fmt: skip
        task = track.task(cell.task).config(cell.method, validation)
    clash = sorted(set(overrides) & (set(task) - {"method_options"}))
    if clash:
        raise ConfigError(f"task {cell.task} fixes {', '.join(clash)}; not an override")
    settings = {f.name for f in fields(RunConfig)}
    options = {**{k: v for k, v in overrides.items() if k not in settings},
               **task.pop("method_options", {}), **(method_options or {})}  # fmt: skip
    options = scoped_options(cell.method, options)
    own = options_class(cell.method).names()
    return {
        **{k: v for k, v in overrides.items() if k in settings}, **task,
        "env": cell.env, "method": cell.method, "seed": cell.seed,
        **({"layouts": cell.layouts} if cell.layouts is not None else {}),
        "run_dir": str(cell.run_dir(out)), "quiet": True, "threads": int(threads),
        "method_options": {k: v for k, v in options.items() if k in own},
    }  # fmt: skip


def check_method_options(methods: Sequence[str], overrides: dict[str, Any] | None,
                         method_options: dict[str, Any] | None) -> None:  # fmt: skip
    """Refuse a setting that is neither the run config's nor an option of some method of the
    grid (a typo would otherwise be dropped by every cell).

    Raises:
        ConfigError: The unknown names, and the options the grid's methods have.
    """
    settings = {f.name for f in fields(RunConfig)}
    given = {k for k, v in (overrides or {}).items() if v is not None and k not in settings}
    given |= set(method_options or {})
    known = {name for m in set(methods) for name in options_class(m).names()}
    prefixed = {options_class(m).flag_prefix + name for m in set(methods)
                for name in options_class(m).names()}  # ``lapo-schedule``: one method's own
    unknown = sorted(given - known - prefixed)
    if unknown:
        raise ConfigError(f"no method of the grid ({', '.join(sorted(set(methods)))}) has "
                          f"option(s) {', '.join(unknown)}; theirs: "
                          f"{', '.join(sorted(known)) or 'none'}")  # fmt: skip

"""The runs of an ``abco bench`` grid, as ``abco report`` reads them, and the tables' names.

:func:`load_runs` reads every ``RUNS_DIR/{env}/{method}/seed{seed}`` folder (its
``final.json``, and its row of ``results.jsonl``), each record checked
(:mod:`abco_train.bench.records`): a damaged one is skipped and counted; :class:`Grid`
indexes them by cell. The
report (:mod:`abco_train.report.write`) and its tables (:mod:`abco_train.report.tables`) build on
these.

Example:
    >>> table_evaluation("AbcoMaze5x5-v0", "test"), table_evaluation("CartPole-v1")
    ('test/paper', 'episodes')
    >>> method_order(["knn-ifo", "abco", "gaifo", "bc", "attention"])
    ['bc', 'abco', 'gaifo', 'attention', 'knn-ifo']
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import abco_envs
from abco_train.bench.records import (
    RecordError,
    Skipped,
    check_final,
    check_metrics_line,
    check_name,
    layouts_of,
    read_json,
    read_json_lines,
    seed_of,
)
from abco_train.bench.results_log import read_results
from abco_train.harness.run_folder import FINAL, METRICS
from abco_train.report.published import PAPER_TABLE1, PUBLISHED_AER
from abco_train.report.stats import CellStats, cell_stats

__all__ = [
    "MAZES", "TABLE1_ENVS", "TABLE1_METHODS", "TABLE2_METHODS", "TABLE2_ENV", "ORDER",
    "LABELS", "GOALS", "CSV_FIELDS", "table_evaluation", "method_order", "env_order",
    "ReportError", "Run", "load_runs", "Grid", "check_baseline",
]  # fmt: skip

MAZES = abco_envs.MAZE_IDS
TABLE1_ENVS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0", *MAZES)
#: The built-in methods of the benchmark (Table 1 re-measured), expected on every env: the
#: trainer's method names -> the tables' labels.
TABLE1_METHODS = {"bc": "BC", "bco": "BCO", "bco-alpha": "BCO(α)", "abco": "ABCO(α)",
                  "iupe": "IUPE", "ilpo": "ILPO", "gaifo": "GAIfO"}  # fmt: skip
#: Table 2 rows (ablation, 5x5 maze) -> the trainer's methods. The paper's "BCO" row repeats
#: Table 1's BCO on the 5x5 maze (P -0.112), i.e. BCO(α).
TABLE2_METHODS = {
    "bco-alpha": "BCO(α)", "bco-alpha-torabi": "BCO(α), Torabi", "attention": "Attention",
    "sampling-partial": "Partial sampling",
    "sampling-whole": "Whole sampling", "abco": "ABCO (attention + partial sampling)",
    "abco-whole": "ABCO (attention + whole sampling)",
}  # fmt: skip
TABLE2_ENV = "AbcoMaze5x5-v0"
#: The built-ins in the tables' order; any other method follows, alphabetically.
ORDER = ("bc", "bco", "bco-alpha", "bco-alpha-torabi", "abco", "iupe", "ilpo", "gaifo", "dilo",
         "lapo", "attention", "sampling-partial", "sampling-whole", "abco-whole")  # fmt: skip
#: Labels of the main table (a method without one is shown by its name).
LABELS = {**TABLE2_METHODS, **TABLE1_METHODS, "dilo": "DILO", "lapo": "LAPO"}

#: The issue's goals (mean over seeds): ABCO's AER >= the paper's and P >= 0.95; IUPE and
#: ILPO at or above their published AER; the seven-method grid within 4 h of wall time.
GOALS = {"aer": {e: PAPER_TABLE1["abco"][e][1] for e in TABLE1_ENVS}, "performance": 0.95,
         "published_aer": PUBLISHED_AER, "wall_s": 4 * 3600.0}  # fmt: skip

CSV_FIELDS = ("table", "env", "method", "evaluation", "metric", "seeds", "mean", "ci_low",
              "ci_high", "iqm", "iqm_ci_low", "iqm_ci_high", "paper", "layouts")  # fmt: skip


def table_evaluation(env: str, split: str = "train") -> str:
    """The ``final.json`` key of a table's numbers: mazes ``{split}/paper``, else ``episodes``."""
    return f"{split}/paper" if abco_envs.is_maze(env) else "episodes"  # no env to make


def method_order(methods: Iterable[str]) -> list[str]:
    """``methods`` in the tables' order: the built-ins of :data:`ORDER`, then the rest."""
    methods = set(methods)
    return [m for m in ORDER if m in methods] + sorted(methods - set(ORDER))


def env_order(env: str) -> tuple[int, str]:
    """Sort key of envs: Table 1's order, then any other env alphabetically."""
    return (TABLE1_ENVS.index(env) if env in TABLE1_ENVS else len(TABLE1_ENVS), env)


class ReportError(ValueError):
    """Nothing to report on, or a bad option (an unknown baseline); the message says which."""


# -- the runs -------------------------------------------------------------------------------


@dataclass
class Run:
    """One cell's run folder: its final evaluation, history and bench row."""

    env: str
    method: str
    seed: int
    path: Path
    final: dict[str, Any] | None
    row: dict[str, Any] = field(default_factory=dict)
    #: K of a run on the first K procedural layouts; ``None``: the standard datasets.
    layouts: int | None = None
    #: Why the run's ``final.json`` was skipped (damaged, or not this cell's), else ``None``.
    damaged: str | None = None
    #: The run folder relative to the grid's, and where the records it skips go.
    where: str = ""
    skipped: list[Skipped] = field(default_factory=list, repr=False, compare=False)
    _history: list[dict[str, Any]] | None = field(default=None, init=False, repr=False,
                                                  compare=False)  # fmt: skip

    @property
    def status(self) -> str:
        """``ok`` (a result), ``unfinished`` (no final.json), ``damaged`` (a final.json that
        was skipped), or the status of a run its method stopped (e.g. ``idm_at_chance``: no
        result, by design)."""
        if self.damaged is not None:
            return "damaged"
        if self.final is None:
            return "unfinished"
        return str(self.final.get("status", "ok"))

    def metrics(self) -> list[dict[str, Any]]:
        """The per-iteration records of ``metrics.jsonl`` (checked; a damaged line is skipped
        and counted in :attr:`skipped`)."""
        if self._history is None:
            self._history = []
            where = f"{self.where}/{METRICS}".lstrip("/")
            try:
                lines = read_json_lines(self.path / METRICS)
            except RecordError as exc:
                self.skipped.append(Skipped(where, str(exc)))
                lines = []
            for number, record in lines:
                try:
                    if isinstance(record, RecordError):
                        raise record
                    self._history.append(check_metrics_line(record))
                except RecordError as exc:
                    self.skipped.append(Skipped(f"{where} line {number}", str(exc)))
        return self._history

    def values(self, evaluation: str, metric: str) -> np.ndarray | None:
        """Per-episode values when recorded, else the one score; ``None`` if absent."""
        score = (self.final or {}).get(evaluation)
        if not isinstance(score, dict) or metric not in score:
            return None
        # Per-episode values exist for returns and P; a success rate is one number per run.
        per_episode = score.get({"aer": "episode_returns",
                                 "performance": "episode_performance"}.get(metric, ""))
        return np.asarray(per_episode if per_episode else [score[metric]], dtype=np.float64)

    def interactions(self, kind: str) -> int | None:
        """Environment interactions of ``kind`` the run spent (``None``: not recorded)."""
        counts = (self.final or {}).get("interactions")
        return int(counts[kind]) if isinstance(counts, dict) and kind in counts else None


def _seed_folders(runs_dir: Path, skipped: list[Skipped]
                  ) -> list[tuple[Path, str, str, int | None, int]]:  # fmt: skip
    """``(folder, env, method, layouts, seed)`` of every run folder under ``runs_dir``; a
    folder whose name cannot be a run's (``seed٣``, ``seed²``, ``layoutsX``, a control
    character in an env's name) is skipped and counted."""
    found = []
    paths = [*runs_dir.glob("*/*/seed*"), *runs_dir.glob("*/*/layouts*/seed*")]
    for path in sorted(paths):
        if not path.is_dir():
            continue
        where = path.relative_to(runs_dir).as_posix()
        has_layouts = len(path.relative_to(runs_dir).parts) == 4
        method_dir = path.parent.parent if has_layouts else path.parent
        try:
            seed = seed_of(path.name)
            if seed is None:
                raise RecordError("not a run folder's name (seed and ASCII digits, e.g. seed3)")
            layouts = layouts_of(path.parent.name) if has_layouts else None
            if has_layouts and layouts is None:
                raise RecordError("not a run folder (layouts and ASCII digits, e.g. layouts100)")
            env = check_name(method_dir.parent.name, "env")
            method = check_name(method_dir.name, "method")
        except RecordError as exc:
            skipped.append(Skipped(where, str(exc)))
            continue
        found.append((path, env, method, layouts, seed))
    return found


def load_runs(runs_dir: str | Path, skipped: list[Skipped] | None = None) -> list[Run]:
    """Every run folder ``{env}/{method}/seed{seed}`` and ``{env}/{method}/layouts{K}/seed{seed}``
    under ``runs_dir`` (finished or not), every record checked as it is read.

    Args:
        runs_dir: The grid's folder.
        skipped: Where every record that is skipped goes (a damaged ``results.jsonl`` row, a
            ``final.json`` that is damaged or another cell's, a folder name that cannot be a
            run's; later, the damaged lines of ``metrics.jsonl`` as the runs read them).
    """
    runs_dir = Path(runs_dir)
    skipped = [] if skipped is None else skipped
    rows = read_results(runs_dir, skipped)
    runs = []
    for path, env, method, layouts, seed in _seed_folders(runs_dir, skipped):
        where = path.relative_to(runs_dir).as_posix()
        final, damaged = None, None
        try:
            final = check_final(read_json(path / FINAL), (env, method, seed, layouts))
        except FileNotFoundError:
            pass
        except RecordError as exc:
            damaged = str(exc)
            skipped.append(Skipped(f"{where}/{FINAL}", damaged))
        runs.append(Run(env, method, seed, path, final, rows.get(where, {}), layouts, damaged,
                        where, skipped))  # fmt: skip
    return runs


class Grid:
    """The runs indexed by (env, method), with the expected seeds and methods."""

    def __init__(self, runs: list[Run]) -> None:
        self.runs = runs
        self.done = [r for r in runs if r.status == "ok"]
        self.stopped = [r for r in runs if r.status not in ("ok", "unfinished", "damaged")]
        self.seeds = sorted({r.seed for r in runs})
        self.methods = method_order({r.method for r in runs})
        self.by_cell: dict[tuple[str, str], list[Run]] = {}
        for r in self.done:
            self.by_cell.setdefault((r.env, r.method), []).append(r)

    @property
    def main_methods(self) -> list[str]:
        """Rows of the main table: Table 1's built-ins and every other method found, except
        Table 2's ablations run only on Table 2's maze (they have their own table)."""
        ablations = set(TABLE2_METHODS) - set(TABLE1_METHODS)
        found = {r.method for r in self.runs
                 if r.method not in ablations or r.env not in (TABLE2_ENV,)}  # fmt: skip
        return method_order(set(TABLE1_METHODS) | found)

    def has(self, env: str, method: str) -> bool:
        """A finished or stopped run of the cell exists."""
        return (env, method) in self.by_cell or any(
            r.env == env and r.method == method for r in self.stopped)

    def by_cell_env(self, env: str) -> list[Run]:
        return [r for r in self.done if r.env == env]

    def stats(self, env: str, method: str, evaluation: str, metric: str) -> CellStats | None:
        groups = [v for r in self.by_cell.get((env, method), [])
                  if (v := r.values(evaluation, metric)) is not None]  # fmt: skip
        return cell_stats(groups)

    def interactions(self, env: str, method: str, kind: str) -> CellStats | None:
        """Interactions of ``kind`` over the cell's finished runs that recorded them."""
        counts = [np.array([float(c)]) for r in self.by_cell.get((env, method), [])
                  if (c := r.interactions(kind)) is not None]  # fmt: skip
        return cell_stats(counts)

    def scores(self, methods: Iterable[str], envs: Iterable[str]
               ) -> dict[str, dict[str, dict[int, float]]]:  # fmt: skip
        """``method -> env -> seed -> P`` of the finished runs (the tables' evaluation)."""
        out: dict[str, dict[str, dict[int, float]]] = {}
        for m in methods:
            for e in envs:
                for r in self.by_cell.get((e, m), []):
                    v = r.values(table_evaluation(e), "performance")
                    if v is not None:
                        out.setdefault(m, {}).setdefault(e, {})[r.seed] = float(v.mean())
        return out


def check_baseline(baseline: str | None, grid: Grid, runs_dir: str | Path) -> str:
    """The probability of improvement's baseline: ``baseline`` (a method of the grid), or abco.

    Raises:
        ReportError: ``baseline`` is not a method of the grid.
    """
    if baseline is not None and baseline not in grid.methods:
        raise ReportError(f"unknown baseline {baseline!r}: not a method of {runs_dir}; methods"
                          f" found: {', '.join(grid.methods)}")  # fmt: skip
    return baseline or "abco"

"""The tuning record of a benchmark track: each method's configurations on the validation
seeds, and the one kept per task family.

A tuning folder holds one ``abco bench --track ... --seeds validation`` grid per configuration
(``TUNING/defaults``, ``TUNING/lr-div3``, ...). For every method and task family (the tasks'
env kind: ``classic`` for vector observations, ``maze``, ``image``) the record gives each
configuration's headline scores, run by run, and their mean over the family's tasks and seeds;
the configuration with the higher mean is kept, and a tie keeps the first (the defaults). A run
its method stopped without a result (e.g. its IDM at chance) counts as score 0, as in the
report. A configuration with a missing run makes no choice: the record says what is missing.
A configuration written ``defaults+rerun`` overlays a second folder on the first: the cells
(task and method) the second holds replace the first's.

``abco report TUNING --tuning defaults,lr-div3`` writes ``tuning.md`` and ``choices.json``.

Example:
    >>> choose({"defaults": 0.5, "lr-div3": 0.5}), choose({"defaults": 0.5, "lr-div3": 0.6})
    ('defaults', 'lr-div3')
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from abco_train.bench.records import Skipped, check_name, escape
from abco_train.bench.tasks import Track
from abco_train.config.fields import ConfigError
from abco_train.config.run import env_kind
from abco_train.report.headline import REFERENCE_METHODS, Cell, split_tracks, task_cells
from abco_train.report.runs import ReportError, load_runs, method_order
from abco_train.report.tables import fmt

__all__ = ["FamilyResult", "TuningRecord", "choose", "tuning_record", "write_tuning"]


@dataclass
class FamilyResult:
    """One method on one task family: per configuration, its runs' scores and their mean."""

    method: str
    family: str
    #: configuration -> ``(task, seed) -> score``
    scores: dict[str, dict[tuple[str, int], float]] = field(default_factory=dict)
    #: configuration -> the ``(task, seed)`` of the family with no record
    missing: dict[str, list[tuple[str, int]]] = field(default_factory=dict)

    def mean(self, config: str) -> float | None:
        """The configuration's mean score over the family's runs (``None``: no run)."""
        values = list(self.scores.get(config, {}).values())
        return float(np.mean(values)) if values else None

    @property
    def choice(self) -> str | None:
        """The configuration kept (``None`` while one has a missing run)."""
        if any(self.missing.values()) or not self.scores:
            return None
        means = {c: self.mean(c) for c in self.scores}
        return choose({c: m for c, m in means.items() if m is not None})


@dataclass
class TuningRecord:
    """Every method's :class:`FamilyResult` over the configurations of a tuning folder."""

    configs: tuple[str, ...]
    families: dict[str, tuple[str, ...]]  # family -> its tasks
    results: dict[tuple[str, str], FamilyResult]  # (method, family) -> result
    #: Records left out (damaged, or not their folder's): where, and why.
    skipped: list[Skipped] = field(default_factory=list)

    def choices(self) -> dict[str, dict[str, str | None]]:
        """``method -> family -> configuration kept`` (``None``: not decided yet)."""
        out: dict[str, dict[str, str | None]] = {}
        for (method, family), result in self.results.items():
            out.setdefault(method, {})[family] = result.choice
        return out


def choose(means: Mapping[str, float]) -> str:
    """The configuration with the highest mean; a tie keeps the earliest (the defaults)."""
    best = max(means.values())
    # a tie (to rounding: means of the same scores summed in another order) keeps the first
    return next(c for c, m in means.items() if m >= best - 1e-9)


def tuning_record(tuning_dir: str | Path, configs: Sequence[str], track: Track,
                  seeds: Sequence[int]) -> TuningRecord:  # fmt: skip
    """The record of ``configs`` (subfolders of ``tuning_dir``, the defaults first) on
    ``track``'s tasks and ``seeds``; the methods are the track's, less the references.

    Raises:
        ReportError: A configuration folder that does not exist.
        ConfigError: A configuration name that is not a plain folder name.
    """
    families: dict[str, list[str]] = {}
    for task in track.tasks:
        families.setdefault(env_kind(task.env), []).append(task.name)
    methods = [m for m in method_order(track.methods) if m not in REFERENCE_METHODS]
    results = {(m, f): FamilyResult(m, f) for m in methods for f in families}
    skipped: list[Skipped] = []
    for config in configs:
        cells = _config_cells(Path(tuning_dir), config, skipped)
        for (method, family), result in results.items():
            scores = result.scores.setdefault(config, {})
            missing = result.missing.setdefault(config, [])
            for task in families[family]:
                cell = cells.get(task, {}).get(method)
                for seed in seeds:
                    if cell is not None and cell.scored and seed in cell.values:
                        scores[(task, seed)] = cell.values[seed]
                    else:
                        missing.append((task, seed))
    return TuningRecord(tuple(configs), {f: tuple(t) for f, t in families.items()}, results,
                        skipped)  # fmt: skip


def _config_cells(tuning_dir: Path, config: str, skipped: list[Skipped]
                  ) -> dict[str, dict[str, Cell]]:  # fmt: skip
    """``task -> method -> Cell`` of a configuration: one folder, or ``BASE+OVER[+...]`` where
    a later folder's cells replace the earlier's of the same task and method (a default that
    changed after the base grid ran: its re-validation's runs stand in for the base's)."""
    cells: dict[str, dict[str, Cell]] = {}
    for part in config.split("+"):
        folder = tuning_dir / check_name(part, "configuration")
        if not folder.is_dir():
            raise ReportError(f"no configuration folder {escape(folder, 200)}")
        found: list[Skipped] = []
        by_task, _ = split_tracks(load_runs(folder, found))
        skipped += [Skipped(f"{part}/{s.where}", s.reason) for s in found]
        for task, by_method in task_cells(by_task).items():
            cells.setdefault(task, {}).update(by_method)
    return cells


def _summary(record: TuningRecord) -> list[str]:
    heads = " | ".join(escape(c, 40) for c in record.configs)
    lines = [f"| Method | Family | {heads} | Kept |",
             "|---|---|" + "---:|" * len(record.configs) + "---|"]  # fmt: skip
    for (method, family), result in record.results.items():
        cells = []
        for config in record.configs:
            mean, n = result.mean(config), len(result.scores.get(config, {}))
            gap = len(result.missing.get(config, []))
            cells.append(f"{fmt(mean) if mean is not None else '–'} ({n} runs"
                         + (f", {gap} missing)" if gap else ")"))  # fmt: skip
        kept = result.choice or "not decided: runs missing"
        lines.append(f"| {escape(method, 60)} | {family} | {' | '.join(cells)} | {kept} |")
    return lines


def _runs(record: TuningRecord, method: str) -> list[str]:
    heads = " | ".join(escape(c, 40) for c in record.configs)
    lines = [f"#### {escape(method, 60)}", "", f"| Task | Seed | {heads} |",
             "|---|---|" + "---:|" * len(record.configs)]  # fmt: skip
    for family, tasks in record.families.items():
        result = record.results[(method, family)]
        keys = sorted({k for s in result.scores.values() for k in s}
                      | {k for m in result.missing.values() for k in m},
                      key=lambda k: (tasks.index(k[0]), k[1]))  # fmt: skip
        for task, seed in keys:
            values = [result.scores.get(c, {}).get((task, seed)) for c in record.configs]
            shown = " | ".join("missing" if v is None else fmt(v) for v in values)
            lines.append(f"| {escape(task, 80)} | {seed} | {shown} |")
    return lines + [""]


def write_tuning(tuning_dir: str | Path, configs: Sequence[str], track: Track,
                 seeds: Sequence[int], out: str | Path | None = None
                 ) -> dict[str, Path]:  # fmt: skip
    """Write ``tuning.md`` and ``choices.json`` of :func:`tuning_record` into ``out``
    (default ``tuning_dir``); the paths written, by name."""
    from abco_train.harness.run_folder import write_atomic

    if not configs:
        raise ConfigError("--tuning names no configuration (e.g. defaults,lr-div3)")
    target = Path(out) if out is not None else Path(tuning_dir)
    if target.exists() and not target.is_dir():
        raise ReportError(f"--out {escape(target, 200)} is not a folder")
    record = tuning_record(tuning_dir, configs, track, seeds)
    target.mkdir(parents=True, exist_ok=True)
    families = ", ".join(f"{f}: {', '.join(t)}" for f, t in record.families.items())
    lines = [f"# Tuning record: {escape(track.name, 80)}", "",
             f"Configurations (the first is the defaults; a tie keeps it): "
             f"{', '.join(record.configs)}. Seeds: {', '.join(map(str, seeds))}. "
             f"Task families: {families}.", "",
             "Each cell: the mean headline score over the family's tasks and seeds (a run its "
             "method stopped without a result counts as 0). Kept: the configuration with the "
             "higher mean.", "", *_summary(record), "", "## Runs", ""]  # fmt: skip
    for method in dict.fromkeys(m for m, _ in record.results):
        lines += _runs(record, method)
    if record.skipped:
        lines += ["## Records left out", "",
                  *(f"- `{escape(s.where, 200)}`: {escape(s.reason, 300)}"
                    for s in record.skipped)]  # fmt: skip
    files = {"record": target / "tuning.md", "choices": target / "choices.json"}
    write_atomic(files["record"], "\n".join(lines))
    choices = {"track": track.name, "configs": list(record.configs), "seeds": list(seeds),
               "choices": record.choices()}  # fmt: skip
    write_atomic(files["choices"], json.dumps(choices, indent=2) + "\n")
    return files

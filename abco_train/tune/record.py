"""The tuning record: Optuna's journal, and what is written from it after every trial.

``OUT/optuna.journal`` holds the studies (Optuna's own format, its storage). From it come
``trials.jsonl`` (one line per finished trial, :class:`TrialRow`'s fields and ``format``),
``choices.json`` (per method and family, the best trial: its settings split into run
settings and method options; a tie keeps the earlier trial, so the defaults win ties) and
``tuning.md``. :func:`read_trials` reads ``trials.jsonl`` back as untrusted input: bounded in
size, every line checked, a damaged line left out and counted.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from abco_train.bench.records import escape
from abco_train.bench.tasks import Track

__all__ = ["FORMAT", "JOURNAL", "TRIALS", "CHOICES", "RECORD", "TrialRow", "journal",
           "trial_rows", "best_trials", "write_record", "read_trials", "load_choices"]  # fmt: skip

FORMAT = 1
JOURNAL, TRIALS, CHOICES, RECORD = "optuna.journal", "trials.jsonl", "choices.json", "tuning.md"
#: ``trials.jsonl`` is refused past this size (a record of 10,000 trials is far below it).
MAX_TRIALS_BYTES = 64 << 20
#: ``choices.json`` is refused past this size.
MAX_CHOICES_BYTES = 1 << 20


@dataclass(frozen=True)
class TrialRow:
    """One finished trial of a method on a task family."""

    track: str
    family: str
    method: str
    trial: int
    defaults: bool
    value: float
    params: dict[str, Any] = field(default_factory=dict)
    #: ``{task}/seed{seed} -> score`` (``None``: the run failed; it counted 0)
    runs: dict[str, float | None] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    #: The track's test seeds when the record was written (none may be among ``seeds``).
    test_seeds: list[int] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    seconds: float = 0.0
    folder: str = ""


def journal(out: Path) -> Any:
    """Optuna's journal storage of a tuning folder."""
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    return JournalStorage(JournalFileBackend(str(out / JOURNAL)))


def trial_rows(out: Path, track: Track) -> list[TrialRow]:
    """Every finished trial of every study in ``out``'s journal, by family, method, trial."""
    import optuna
    from optuna.trial import TrialState

    storage = journal(out)
    tests = track.all_test_seeds()
    rows = []
    for name in sorted(optuna.get_all_study_names(storage)):
        family, _, method = name.partition("/")
        study = optuna.load_study(study_name=name, storage=storage)
        for t in study.trials:
            if t.state != TrialState.COMPLETE or t.value is None:
                continue
            attrs = t.user_attrs
            rows.append(TrialRow(track.name, family, method, t.number,
                                 bool(attrs.get("defaults")), float(t.value), dict(t.params),
                                 dict(attrs.get("runs", {})), list(attrs.get("seeds", [])),
                                 tests, list(attrs.get("failures", [])),
                                 float(attrs.get("seconds", 0.0)),
                                 str(attrs.get("folder", ""))))  # fmt: skip
    return rows


def best_trials(rows: list[TrialRow]) -> dict[tuple[str, str], TrialRow]:
    """``(method, family) -> its best trial``; a tie keeps the earlier (the defaults)."""
    best: dict[tuple[str, str], TrialRow] = {}
    for row in sorted(rows, key=lambda r: r.trial):
        kept = best.get((row.method, row.family))
        if kept is None or row.value > kept.value + 1e-9:
            best[(row.method, row.family)] = row
    return best


def write_record(out: Path, track: Track) -> dict[str, Path]:
    """Write ``trials.jsonl``, ``choices.json`` and ``tuning.md`` of ``out``'s journal."""
    from abco_train.harness.run_folder import write_atomic
    from abco_train.tune.space import split_params

    rows = trial_rows(out, track)
    lines = "".join(json.dumps({"format": FORMAT, **asdict(r)}) + "\n" for r in rows)
    choices: dict[str, dict[str, Any]] = {}
    for (method, family), row in best_trials(rows).items():
        settings, options = split_params(method, row.params)
        n = sum(r.method == method and r.family == family for r in rows)
        choices.setdefault(method, {})[family] = {
            "trial": row.trial, "value": row.value, "defaults": row.defaults, "trials": n,
            "run_settings": settings, "method_options": options}  # fmt: skip
    files = {"trials": out / TRIALS, "choices": out / CHOICES, "record": out / RECORD}
    write_atomic(files["trials"], lines)
    write_atomic(files["choices"], json.dumps({"format": FORMAT, "track": track.name,
                                               "choices": choices}, indent=2) + "\n")
    write_atomic(files["record"], "\n".join(_markdown(rows, track)) + "\n")
    return files


def _markdown(rows: list[TrialRow], track: Track) -> list[str]:
    from abco_train.tune.space import describe

    best = best_trials(rows)
    lines = [f"# Tuning record: {escape(track.name, 80)}", "",
             f"Validation seeds {_seeds_by_family(rows)} (maze runs on "
             "validation layouts). A trial's value is the mean headline score of its runs, a "
             "failed run counting 0; the first trial runs the method's defaults (the next "
             "where it was cut short and run again); a tie keeps the earlier trial.", "",
             "| Family | Method | Trials | Defaults | Best | Best trial | Its settings |",
             "|---|---|---:|---:|---:|---:|---|"]  # fmt: skip
    for (method, family), row in best.items():
        mine = [r for r in rows if r.method == method and r.family == family]
        default = next((f"{r.value:.3f}" for r in mine if r.defaults), "–")
        lines.append(f"| {family} | {escape(method, 60)} | {len(mine)} | {default} | "
                     f"{row.value:.3f} | {row.trial} | {_settings(row.params)} |")
    lines += ["", "## Search spaces", ""]
    lines += [f"- {family}, `{escape(method, 60)}`: "
              f"{describe(method, _resolved(track, method, family, rows))}"
              for method, family in dict.fromkeys((r.method, r.family) for r in rows)]
    lines += ["", "## Trials", "", "| Family | Method | Trial | Value | Failed runs | Settings |",
              "|---|---|---:|---:|---:|---|"]  # fmt: skip
    for r in rows:
        lines.append(f"| {r.family} | {escape(r.method, 60)} | {r.trial} | {r.value:.3f} | "
                     f"{len(r.failures)} | {_settings(r.params)} |")
    return lines


def _seeds_by_family(rows: list[TrialRow]) -> str:
    """``"classic 100, 101, 102; maze 100"``: each family's seeds, since a family whose cells
    cost more may be tuned on fewer of them."""
    families = {r.family: set[int]() for r in rows}
    for r in rows:
        families[r.family].update(r.seeds)
    return "; ".join(f"{family} {', '.join(map(str, sorted(seeds))) or 'none'}"
                     for family, seeds in sorted(families.items())) or "none yet"


def _resolved(track: Track, method: str, family: str, rows: list[TrialRow]) -> list[Any] | None:
    """The method's resolved options on the family's tasks its trials ran (``None``: a task
    the track no longer has; the whole space is described)."""
    from abco_train.config.fields import ConfigError
    from abco_train.tune.space import resolved_options

    tasks = list(dict.fromkeys(key.rpartition("/seed")[0] for r in rows
                               if (r.method, r.family) == (method, family) for key in r.runs))
    if not tasks:  # no run to tell the family's tasks by
        return None
    try:
        return resolved_options(track, method, tasks)
    except (ConfigError, KeyError, ValueError):
        return None


def _settings(params: Mapping[str, Any]) -> str:
    if not params:
        return "defaults"
    return ", ".join(f"`{k}={v:.3g}`" if isinstance(v, float) else f"`{k}={v}`"
                     for k, v in params.items())  # fmt: skip


def read_trials(path: Path) -> tuple[list[TrialRow], int]:
    """The rows of a ``trials.jsonl`` and the number of damaged lines left out.

    Raises:
        RunFolderError: Not a regular file, or larger than :data:`MAX_TRIALS_BYTES`.
        OSError: It cannot be read.
    """
    from abco_train.harness.run_folder import read_capped

    rows, damaged = [], 0
    for line in read_capped(path, MAX_TRIALS_BYTES).decode("utf-8", "replace").splitlines():
        if not line.strip():
            continue
        try:
            rows.append(_row(json.loads(line)))
        except (ValueError, TypeError, KeyError, RecursionError):
            damaged += 1
    return rows, damaged


def _row(data: Any) -> TrialRow:
    """A checked :class:`TrialRow` (``ValueError``/``TypeError``/``KeyError``: damaged)."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError("not a trial row of this format")
    text = {k: data[k] for k in ("track", "family", "method", "folder")}
    if not all(isinstance(v, str) and len(v) <= 200 for v in text.values()):
        raise ValueError("a name that is not short text")
    trial, value, seconds = data["trial"], data["value"], data["seconds"]
    if type(trial) is not int or trial < 0 or not isinstance(data["defaults"], bool):
        raise ValueError("a bad trial number")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
               for v in (value, seconds)):  # fmt: skip
        raise ValueError("a value that is not a finite number")
    seeds, tests = data["seeds"], data["test_seeds"]
    if not all(isinstance(s, list) and all(type(x) is int for x in s) for s in (seeds, tests)):
        raise ValueError("seeds that are not whole numbers")
    params, runs, failures = data["params"], data["runs"], data["failures"]
    if not isinstance(params, dict) or not isinstance(runs, dict) or not isinstance(failures,
                                                                                    list):
        raise ValueError("settings, runs or failures of the wrong kind")
    return TrialRow(text["track"], text["family"], text["method"], trial, data["defaults"],
                    float(value), params, runs, seeds, tests, [str(f) for f in failures],
                    float(seconds), text["folder"])  # fmt: skip


def load_choices(path: str | Path, track: Track
                 ) -> dict[tuple[str, str], tuple[dict[str, Any], dict[str, Any]]]:  # fmt: skip
    """The settings a ``choices.json`` keeps: ``(method, family) -> (run settings, method
    options)``, every one checked against the method's search space (a file from elsewhere
    sets nothing a tuner could not have chosen).

    Raises:
        ConfigError: Not a choices file of this format, another track's (a budget curve's
            track takes the choices of the track it varies), an unknown method or family, a
            setting outside its method's search space.
    """
    from abco_train.config.fields import ConfigError
    from abco_train.harness.run_folder import RunFolderError, read_capped
    from abco_train.tune.space import FAMILIES, split_params

    where = f"--choices {escape(path, 200)}"
    try:
        data = json.loads(read_capped(path, MAX_CHOICES_BYTES))
    except (RunFolderError, OSError, ValueError, RecursionError) as exc:
        raise ConfigError(f"{where}: {escape(exc, 200)}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(
            data.get("choices"), dict):  # fmt: skip
        raise ConfigError(f"{where} is not an `abco tune` choices.json (format {FORMAT})")
    if data.get("track") != track.tuning_name:
        raise ConfigError(f"{where} was tuned on track {escape(data.get('track'), 80)!r}, "
                          f"not {track.tuning_name!r}")  # fmt: skip
    out = {}
    for method, families in data["choices"].items():
        if not isinstance(families, dict):
            raise ConfigError(f"{where}: {escape(method, 80)} is not a table of families")
        for family, entry in families.items():
            if family not in FAMILIES or not isinstance(entry, dict):
                raise ConfigError(f"{where}: {escape(method, 80)}: bad family "
                                  f"{escape(family, 40)!r}")  # fmt: skip
            params = {**_mapping(entry, "run_settings", where), **_mapping(
                entry, "method_options", where)}  # fmt: skip
            _check_params(str(method), params, where)
            out[(str(method), family)] = split_params(str(method), params)
    return out


def _mapping(entry: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    from abco_train.config.fields import ConfigError

    value = entry.get(key, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: {key} is not a table")
    return value


def _check_params(method: str, params: dict[str, Any], where: str) -> None:
    """Every setting in ``method``'s search space, its value inside its range."""
    from abco_train.config.fields import ConfigError
    from abco_train.tune.space import method_space

    space = method_space(method)
    for name, value in params.items():
        if name not in space:
            raise ConfigError(f"{where}: {escape(method, 80)} has no tunable setting "
                              f"{escape(name, 80)!r}")  # fmt: skip
        search, kind = space[name]
        if not search.contains(value, kind):
            raise ConfigError(f"{where}: {escape(method, 80)}'s {name} = "
                              f"{escape(value, 40)} is outside {search.describe(kind)}")

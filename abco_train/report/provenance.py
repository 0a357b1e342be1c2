"""Where a grid's records come from: the code that made them, and the training time they took.

Code versions: a record (``final.json``) carries ``code_version`` ``{"version": package
version, "source": short digest of the training and evaluation code}``. The report compares
each record's source digest with the current code's
(:func:`abco_train.harness.runtime.code_version`) and flags, per task (or env) and method, the
records made by another version and those without one (older records): their numbers may not
be comparable with the rest.

Training time: each record's ``seconds`` (its training iterations, each with its evaluation;
start-up and the final evaluation not included) summed over the grid, and per task (or env)
and method, so that how long a grid took is measured by the report.

Example:
    >>> this = {"version": "1.0", "source": "ab12"}
    >>> version_state({"code_version": this}, this), version_state({}, this)
    ('this', 'none')
    >>> version_state({"code_version": {"version": "0.9", "source": "ff00"}}, this)
    'other'
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from abco_train.bench.records import escape
from abco_train.report.runs import Run, env_order, method_order

__all__ = ["MAX_VERSION_ROWS", "current_code_version", "version_state", "group_of",
           "flagged_counts", "versions_section", "training_time"]  # fmt: skip

#: Rows of the code-version table, one per (task, method); past it, one per task.
MAX_VERSION_ROWS = 40
_STATE_TITLES = {"this": "This code", "other": "Another version", "none": "No version",
                 "unknown": "Not comparable"}  # fmt: skip


def current_code_version() -> tuple[dict[str, str] | None, str]:
    """``(the current code's {version, source}, "")``, or ``(None, why it is unknown)``."""
    try:
        from abco_train.harness import runtime
    except ImportError as exc:  # the trainer's dependencies (torch) are missing
        return None, f"abco_train.harness.runtime cannot be imported ({exc})"
    get = getattr(runtime, "code_version", None)
    if get is None:
        return None, "this abco has no abco_train.harness.runtime.code_version"
    found = get()
    if not (isinstance(found, dict) and all(isinstance(found.get(k), str)
                                            for k in ("version", "source"))):  # fmt: skip
        return None, "abco_train.harness.runtime.code_version() gave no {version, source}"
    return {"version": found["version"], "source": found["source"]}, ""


def version_state(final: Mapping[str, Any], current: Mapping[str, str] | None) -> str:
    """``this`` (the record's source digest is the current code's), ``other``, ``none`` (the
    record has no code version) or ``unknown`` (the current code's version is unknown)."""
    version = final.get("code_version")
    if not isinstance(version, dict):
        return "none"
    if current is None:
        return "unknown"
    return "this" if version.get("source") == current["source"] else "other"


def group_of(run: Run) -> str:
    """The task of a run's record, else its folder's env (or task) name."""
    task = (run.final or {}).get("task")
    return task if isinstance(task, str) else run.env


def flagged_counts(runs: Sequence[Run], current: Mapping[str, str] | None
                   ) -> dict[tuple[str, str], dict[str, int]]:  # fmt: skip
    """``(task or env, method) -> state -> records`` of every run with a record."""
    out: dict[tuple[str, str], dict[str, int]] = {}
    for r in runs:
        if r.final is not None:
            counts = out.setdefault((group_of(r), r.method), dict.fromkeys(_STATE_TITLES, 0))
            counts[version_state(r.final, current)] += 1
    return out


def versions_section(runs: Sequence[Run], current: Mapping[str, str] | None, why: str
                     ) -> list[str]:  # fmt: skip
    """The code-version section: the current code's version, the records' counts, and a
    table of the (task or env, method) groups with records flagged."""
    counts = flagged_counts(runs, current)
    totals = {s: sum(c[s] for c in counts.values()) for s in _STATE_TITLES}
    n = sum(totals.values())
    if current is None:
        lines = [f"The current code's version is unknown ({escape(why)}): no record can be"
                 " compared with it."]  # fmt: skip
    else:
        lines = [f"This code: abco {escape(current['version'], 64)}, source"
                 f" {escape(current['source'], 64)}."]  # fmt: skip
    if not n:
        return [*lines, "No run has a record yet."]
    if totals["this"] == n:
        return [*lines, f"Every one of the {n} record(s) was made by this code."]
    others = sorted({(str(r.final["code_version"].get("version")),
                      str(r.final["code_version"].get("source"))) for r in runs
                     if r.final is not None and version_state(r.final, current) == "other"})
    named = ", ".join(f"abco {escape(v, 64)} source {escape(s, 64)}" for v, s in others[:5])
    named = f" ({named}{', ...' if len(others) > 5 else ''})" if others else ""
    unknown = f", {totals['unknown']} not comparable" if totals["unknown"] else ""
    lines += ["", f"{n} record(s): {totals['this']} made by this code, {totals['other']} by"
              f" another version{named}, {totals['none']} without a code version (older"
              f" records){unknown}. A record not made by this code may differ from it in what it"
              " measures: compare with care.", ""]  # fmt: skip
    flagged = {k: c for k, c in counts.items() if c["this"] < sum(c.values())}
    if len(flagged) > MAX_VERSION_ROWS:  # one row per task (or env)
        merged: dict[tuple[str, str], dict[str, int]] = {}
        for (group, _), c in flagged.items():
            into = merged.setdefault((group, "every method"), dict.fromkeys(_STATE_TITLES, 0))
            for s, k in c.items():
                into[s] += k
        flagged = merged
    states = [s for s in _STATE_TITLES if s != "unknown" or totals["unknown"]]
    head = "| Task / env | Method | Records |" + "".join(f" {_STATE_TITLES[s]} |" for s in states)
    lines += [head, "|" + "---|" * head.count(" |")]
    order = {m: i for i, m in enumerate(method_order({m for _, m in flagged}))}
    for (group, method), c in sorted(flagged.items(), key=lambda kv: (
            env_order(kv[0][0]), order[kv[0][1]])):  # fmt: skip
        lines.append(f"| {escape(group)} | {escape(method)} | {sum(c.values())} | "
                     + " | ".join(str(c[s]) for s in states) + " |")
    return lines


def training_time(runs: Sequence[Run]) -> list[str]:
    """The grid's training time from its records' ``seconds``: the total, then a table of
    minutes per task (or env) and method with the totals."""
    seconds: dict[tuple[str, str], float] = {}
    without = 0
    for r in runs:
        if r.final is None:
            continue
        value = r.final.get("seconds")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            key = (group_of(r), r.method)
            seconds[key] = seconds.get(key, 0.0) + float(value)
        else:
            without += 1
    total = sum(seconds.values())
    n = sum(1 for r in runs if r.final is not None) - without
    lines = [f"- Training wall time summed over the runs: {total:,.1f} s ({total / 3600:.2f} h)"
             f" over {n} record(s)" + (f" ({without} record(s) do not carry it)" if without
                                       else "")
             + "; final.json `seconds`: every training iteration with its evaluation, start-up"
             " and the final evaluation not included. Runs that ran at once overlap: the"
             " grid's elapsed time is the sessions' above."]  # fmt: skip
    if not seconds:
        return lines
    groups = sorted({g for g, _ in seconds}, key=env_order)
    methods = method_order({m for _, m in seconds})
    head = "| Task / env |" + "".join(f" {escape(m, 60)} |" for m in methods) + " Total |"
    lines += ["", "Training time per task (or env) and method, minutes summed over runs:", "",
              head, "|" + "---|" * head.count(" |")]  # fmt: skip
    for g in groups:
        row = [seconds.get((g, m)) for m in methods]
        lines.append(f"| {escape(g)} | " + " | ".join("–" if s is None else f"{s / 60:,.1f}"
                                                       for s in row)
                     + f" | {sum(s or 0.0 for s in row) / 60:,.1f} |")  # fmt: skip
    per_method = [sum(seconds.get((g, m), 0.0) for g in groups) / 60 for m in methods]
    lines.append("| Total | " + " | ".join(f"{s:,.1f}" for s in per_method)
                 + f" | {total / 60:,.1f} |")  # fmt: skip
    return lines

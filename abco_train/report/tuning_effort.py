"""The tuning effort behind a grid (``abco report RUNS --tuned-by TUNING``): the trials of
every method per task family, read from the ``trials.jsonl`` of an ``abco tune`` folder, and
what a reviewer checks first: the same number of trials for every method, at least the
benchmark's, none on a test seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from abco_train.bench.records import escape
from abco_train.report.runs import ReportError
from abco_train.tune.record import TRIALS, TrialRow, best_trials, read_trials
from abco_train.tune.study import BENCHMARK_TRIALS

__all__ = ["section"]


def section(tuned_by: str | Path, methods: Sequence[str]) -> list[str]:
    """The report's "Tuning effort" lines for the grid's ``methods`` (its references left out).

    Raises:
        ReportError: ``tuned_by`` holds no readable ``trials.jsonl``.
    """
    from abco_train.harness.run_folder import RunFolderError

    path = Path(tuned_by) / TRIALS
    try:
        rows, damaged = read_trials(path)
    except (RunFolderError, OSError) as exc:
        raise ReportError(f"--tuned-by: cannot read {escape(path, 200)}: "
                          f"{escape(exc, 200)}") from None  # fmt: skip
    counts: dict[tuple[str, str], list[TrialRow]] = {}
    for row in rows:
        counts.setdefault((row.method, row.family), []).append(row)
    families = sorted({f for _, f in counts})
    lines = ["## Tuning effort", "",
             f"From `{escape(tuned_by, 200)}`: every finished trial per method and task "
             "family (the first runs the method's defaults); a trial's value is its runs' mean "
             "headline score on the validation seeds.", "",
             "| Method | Family | Trials | Defaults | Best (trial) | Seeds |",
             "|---|---|---:|---:|---:|---|"]  # fmt: skip
    best = best_trials(rows)
    for (method, family), mine in sorted(counts.items()):
        default = next((f"{r.value:.3f}" for r in mine if r.defaults), "–")
        top = best[(method, family)]
        seeds = sorted({s for r in mine for s in r.seeds})
        lines.append(f"| {escape(method, 60)} | {escape(family, 20)} | {len(mine)} | {default} "
                     f"| {top.value:.3f} ({top.trial}) | {', '.join(map(str, seeds))} |")
    return lines + ["", *_checks(counts, families, methods, rows, damaged)]


def _checks(counts: dict[tuple[str, str], list[TrialRow]], families: list[str],
            methods: Sequence[str], rows: list[TrialRow], damaged: int) -> list[str]:  # fmt: skip
    lines = []
    for family in families:
        per_method = {m: len(counts.get((m, family), [])) for m in methods}
        if len(set(per_method.values())) == 1:
            n = next(iter(per_method.values()), 0)
            low = f" (the benchmark asks {BENCHMARK_TRIALS})" if n < BENCHMARK_TRIALS else ""
            lines.append(f"- {family}: every method of the grid had {n} trials{low}.")
        else:
            shown = ", ".join(f"{escape(m, 60)} {n}" for m, n in per_method.items())
            lines.append(f"- {family}: **unequal tuning**: {shown}.")
    on_test = sorted({f"{r.method} ({r.family}, trial {r.trial})" for r in rows
                      if set(r.seeds) & set(r.test_seeds)})  # fmt: skip
    lines.append(f"- **Trials on test seeds**: {escape(', '.join(on_test), 600)}." if on_test
                 else "- No trial ran on a test seed.")  # fmt: skip
    if damaged:
        lines.append(f"- {damaged} damaged line(s) of `{TRIALS}` left out.")
    return lines

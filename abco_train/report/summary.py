"""The first section of ``abco report``: what ran, what did not, and the records it skipped.

Before any table, the report says how many cells finished, failed, were stopped by their
method, are unfinished or have a damaged record, and how many are missing from the grid the
runs span: on each environment, every method found there times every seed (and number of
training layouts) found there. One line per environment names the cells that did not
finish. Then the records the report skipped (:class:`abco_train.bench.records.Skipped`), each
with its reason.

Example:
    >>> from pathlib import Path
    >>> runs = [Run("CartPole-v1", "abco", s, Path(), {"status": "ok"}) for s in (0, 1)]
    >>> runs.append(Run("CartPole-v1", "bc", 0, Path(), None, {"status": "failed"}))
    >>> print("\\n".join(summary(runs, [])))  # doctest: +NORMALIZE_WHITESPACE
    3 cells: 2 finished, 1 failed; 1 missing from the grid they span (on each environment,
    every method found there × every seed found there).
    <BLANKLINE>
    - CartPole-v1: 2 methods × seeds 0-1, 2 of 4 cells finished; bc: seed 0 failed,
    seed 1 missing
    <BLANKLINE>
    No record skipped: every record read is valid.
"""

from __future__ import annotations

from collections.abc import Sequence

from abco_train.bench.records import Skipped, escape
from abco_train.report.runs import Run, env_order, method_order
from abco_train.report.tables import seed_text

__all__ = ["SHOWN_SKIPPED", "summary", "state_of", "skipped_lines"]

#: Skipped records listed one by one; the rest are counted.
SHOWN_SKIPPED = 20

#: The states of a cell, in the order the summary names them.
STATES = ("finished", "failed", "stopped", "unfinished", "damaged", "missing")
_STATE_TEXT = {"stopped": "stopped by their method", "damaged": "with a damaged final.json"}


def state_of(run: Run) -> str:
    """``finished``, ``failed`` (its bench row says so), ``stopped`` (by its method's health
    check), ``unfinished`` or ``damaged`` (a skipped final.json)."""
    status = run.status
    if status == "ok":
        return "finished"
    if status == "unfinished":
        return "failed" if run.row.get("status") == "failed" else "unfinished"
    return status if status == "damaged" else "stopped"


def summary(runs: Sequence[Run], skipped: Sequence[Skipped]) -> list[str]:
    """The section's Markdown lines: the counts, one line per environment, the skipped records."""
    states: dict[tuple[str, str, int | None, int], str] = {
        (r.env, r.method, r.layouts, r.seed): state_of(r) for r in runs}  # fmt: skip
    lines: list[str] = []
    counts: dict[str, int] = dict.fromkeys(STATES, 0)
    for env in sorted({r.env for r in runs}, key=env_order):
        line, missing = _env_line(env, [r for r in runs if r.env == env], states)
        lines.append(line)
        counts["missing"] += missing
    for state in states.values():
        counts[state] += 1
    parts = [f"{counts['finished']} finished"] + [
        f"{counts[s]} {_STATE_TEXT.get(s, s)}" for s in STATES[1:-1] if counts[s]]
    head = (f"{len(states)} cells: {', '.join(parts)}; "
            f"{counts['missing'] or 'none'} missing from the grid they span (on each environment,"
            " every method found there × every seed found there).")  # fmt: skip
    return [head, "", *lines, "", *skipped_lines(skipped)]


def _env_line(env: str, runs: list[Run], states: dict[tuple[str, str, int | None, int], str]
              ) -> tuple[str, int]:  # fmt: skip
    """The environment's line (its cells finished of those its grid spans, and which did not
    finish), and how many of its cells are missing."""
    methods = method_order({r.method for r in runs})
    seeds = sorted({r.seed for r in runs})
    layouts = sorted({r.layouts for r in runs}, key=lambda k: -1 if k is None else k)
    expected = len(methods) * len(seeds) * len(layouts)
    done, missing, notes = 0, 0, []
    for method in methods:
        for k in layouts:
            by_state: dict[str, list[int]] = {}
            for seed in seeds:
                by_state.setdefault(states.get((env, method, k, seed), "missing"), []).append(seed)
            done += len(by_state.pop("finished", []))
            missing += len(by_state.get("missing", []))
            if by_state:
                name = escape(method) + ("" if k is None or layouts == [k] else f" (K {k:,})")
                notes.append(f"{name}: " + ", ".join(f"{seed_text(s)} {state}" for state, s in
                                                    sorted(by_state.items(), key=_order)))
    span = (f"{len(methods)} method{'s' if len(methods) != 1 else ''} × {seed_text(seeds)}"
            + ("" if layouts == [None] else " × layouts " + ", ".join(
                "standard" if k is None else f"{k:,}" for k in layouts)))  # fmt: skip
    line = f"- {escape(env)}: {span}, {done} of {expected} cells finished"
    return line + ("; " + "; ".join(notes) if notes else ""), missing


def _order(item: tuple[str, list[int]]) -> int:
    return STATES.index(item[0])


def skipped_lines(skipped: Sequence[Skipped]) -> list[str]:
    """The skipped records: a count, then the first :data:`SHOWN_SKIPPED` with their reason."""
    if not skipped:
        return ["No record skipped: every record read is valid."]
    lines = [f"{len(skipped)} record{'s' if len(skipped) != 1 else ''} skipped (damaged, or not"
             " what abco writes; a run whose final.json is skipped counts as not finished):",
             ""]  # fmt: skip
    lines += [f"- {s}" for s in skipped[:SHOWN_SKIPPED]]
    if len(skipped) > SHOWN_SKIPPED:
        lines.append(f"- and {len(skipped) - SHOWN_SKIPPED:,} more")
    return lines

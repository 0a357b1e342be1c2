"""The command line's numbered lists: seeds and numbers of layouts, bounded before any list is
built (ASCII digits, each value in its range, at most :data:`MAX_CELLS` of them).

Example:
    >>> parse_seeds("0-2,7"), parse_layouts("100,1000")
    ([0, 1, 2, 7], [100, 1000])
"""

from __future__ import annotations

import re

from abco_train.bench.records import escape
from abco_train.config.limits import MAX_SEED
from abco_train.config.run import MAX_LAYOUTS, ConfigError

__all__ = ["MAX_CELLS", "parse_seeds", "parse_layouts"]

#: Most cells of one grid (its plan, configs and rows are held in memory, and
#: ``results.jsonl`` is rewritten after every cell); also the most seeds of one ``--seeds``.
MAX_CELLS = 100_000
_RANGE = re.compile(r"([0-9]+)(?:\s*-\s*([0-9]+))?", re.ASCII)


def _ranges(text: str, what: str, low: int, high: int, example: str) -> list[int]:
    """The integers of ``"0-4,7"``-style text (ASCII digits; order kept, no repeats), each in
    ``[low, high]`` and at most :data:`MAX_CELLS` of them, every bound checked before any list
    is built.

    Raises:
        ConfigError: A malformed part, a value out of range, an empty range, too many values.
    """
    found: dict[int, None] = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        m = _RANGE.fullmatch(part)
        if m is None:
            raise ConfigError(f"bad {what} {escape(part, 40)!r}; expected e.g. {example}")
        if any(len(g) > 12 for g in m.groups() if g):
            raise ConfigError(f"{what} {escape(part, 40)!r} is out of range ({low} to {high:,})")
        first = int(m.group(1))
        last = first if m.group(2) is None else int(m.group(2))
        if last < first:
            raise ConfigError(f"empty {what} {part!r}")
        if first < low or last > high:
            raise ConfigError(f"{what} {part!r} is out of range ({low} to {high:,})")
        if last - first + 1 > MAX_CELLS - len(found):
            raise ConfigError(f"more than {MAX_CELLS:,} values in {escape(text, 60)!r}, the most"
                              " a grid holds")  # fmt: skip
        found.update(dict.fromkeys(range(first, last + 1)))
    return list(found)


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-4"``, ``"0,3,5"`` or mixes like ``"0-2,7"`` (order kept, no repeats):
    ASCII digits, each seed at most :data:`~abco_train.config.run.MAX_SEED`, at most
    :data:`MAX_CELLS` of them (checked before any list is built).

    Raises:
        ConfigError: A malformed part, an empty range, a seed out of range, too many seeds.
    """
    seeds = _ranges(text, "seed range", 0, MAX_SEED, "0-4 or 0,2,5")
    if not seeds:
        raise ConfigError("no seeds given")
    return seeds


def parse_layouts(text: str) -> list[int]:
    """Numbers of training layouts from ``"100,1000,10000"`` (``10k`` and ``1,000``-style
    thousands are not accepted: plain integers, comma-separated; order kept, no repeats),
    each from 1 to :data:`~abco_train.config.run.MAX_LAYOUTS`.

    Raises:
        ConfigError: Not a positive integer, or over the limit.
    """
    if any(p.strip() and "-" in p for p in text.split(",")):
        raise ConfigError(f"bad --layouts value {escape(text, 40)!r}; expected positive"
                          " integers such as 100,1000,10000")  # fmt: skip
    out = _ranges(text, "--layouts value", 1, MAX_LAYOUTS, "100,1000,10000")
    if not out:
        raise ConfigError("no --layouts given")
    return out

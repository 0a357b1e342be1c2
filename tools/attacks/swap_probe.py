"""Probe of family 4, run in a process of its own: read a dataset file through a DataLoader
while the file is swapped for another valid dataset, and say what the items were.

Usage: ``python swap_probe.py MODE TARGET OTHER WORKERS``; MODE is ``before`` (swapped once
the torch view exists, before the first epoch), ``mid`` (after the third batch of two
epochs), ``inplace`` (overwritten in place, same inode, after the third batch) or
``truncated`` (replaced by a truncated copy of itself before the first epoch). Prints one
JSON line: how many items were those of the original file only (``a``), of the other file
only (``b``), of both (``both``: the files agree there), of neither (``mixed``: parts of
both), and the error raised, if any.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
from pathlib import Path
from typing import Any


def signatures(path: Path) -> list[tuple[str, ...]]:
    """One signature per item of ``path``'s torch view (read into memory, then closed)."""
    import abco_data

    ds = abco_data.open_dataset(path)
    view = ds.torch_dataset(in_memory=True)
    out = [_signature(view[i]) for i in range(len(view))]
    ds.close()
    return out


def _signature(item: Any) -> tuple[str, ...]:
    return tuple(hashlib.sha1(x.numpy().tobytes()).hexdigest()[:16] for x in item)


def swap(mode: str, target: Path, other: Path, spare: Path) -> None:
    """Put ``other``'s bytes at ``target`` the way ``mode`` says."""
    if mode == "inplace":
        data = other.read_bytes()
        with target.open("r+b") as f:
            f.write(data)
            f.truncate(len(data))
            f.flush()
            os.fsync(f.fileno())
    elif mode == "truncated":
        data = target.read_bytes()
        spare.write_bytes(data[: len(data) // 2])
        os.replace(spare, target)
    else:
        shutil.copy(other, spare)
        os.replace(spare, target)


def main() -> None:
    """Run the probe of ``sys.argv`` and print its JSON line."""
    from torch.utils.data import DataLoader

    import abco_data

    mode, target, other, workers = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), \
        int(sys.argv[4])  # fmt: skip
    truth_a, truth_b = signatures(target), signatures(other)
    counts = {"a": 0, "b": 0, "both": 0, "mixed": 0, "items": 0, "expected": len(truth_a)}
    spare = target.with_name(target.name + ".incoming")
    ds = abco_data.open_dataset(target)
    view = ds.torch_dataset()
    if mode in ("before", "truncated"):
        swap(mode, target, other, spare)
    try:
        epochs = 1 if mode in ("before", "truncated") else 2
        for epoch in range(epochs):
            loader = DataLoader(view, batch_size=64, num_workers=workers, shuffle=False)
            for b, batch in enumerate(loader):
                if epoch == 0 and b == 3 and mode in ("mid", "inplace"):
                    swap(mode, target, other, spare)
                for j in range(len(batch[0])):
                    i = b * 64 + j
                    sig = _signature([x[j] for x in batch])
                    counts["items"] += 1
                    in_a = i < len(truth_a) and sig == truth_a[i]
                    in_b = i < len(truth_b) and sig == truth_b[i]
                    key = "both" if in_a and in_b else "a" if in_a else "b" if in_b else "mixed"
                    counts[key] += 1
    except Exception as exc:  # what the reader said, for the judge
        message = str(exc)
        print(json.dumps({**counts, "error": type(exc).__name__, "message": message[-600:],
                          "names_file": str(target) in message or target.name in message}))
        return
    print(json.dumps(counts))


if __name__ == "__main__":
    main()

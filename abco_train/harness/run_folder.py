"""The run folder's layout, in one place, and the reads that need no torch.

A run folder holds::

    config.json        the resolved config
    metrics.jsonl      one line per iteration: training stats, evaluation, I_s composition,
                       the IDM's label distribution on the expert data, seconds
    checkpoint.pt      the latest iteration's full state (method, rngs); re-running the same
                       command resumes after it
    final.json         the final evaluation (mazes: train and test splits, both protocols)
    metrics.png, labels.png, paths_{split}.png   the plots

Files are written whole or not at all (:func:`write_atomic`, on
:func:`abco_data.files.atomic_target`): a killed run never leaves a half-written
``final.json`` or checkpoint, and the temporaries of killed runs are removed on the next write.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from abco_data.files import atomic_target
from abco_train.methods.registry import identity

__all__ = ["CONFIG", "METRICS", "CHECKPOINT", "FINAL", "RunFolderError", "write_atomic",
           "read_json", "finished_result", "config_differences"]  # fmt: skip

CONFIG = "config.json"
METRICS = "metrics.jsonl"
CHECKPOINT = "checkpoint.pt"
FINAL = "final.json"


class RunFolderError(ValueError):
    """The run folder cannot be used as asked (it holds another config, or damaged files)."""


def write_atomic(path: str | os.PathLike[str], write: Callable[[Path], Any] | str) -> Path:
    """Write ``path`` through a temporary file in the same folder, then rename it into place.

    Args:
        path: The destination.
        write: The text to write, or ``write(tmp_path)`` that writes the file itself (e.g.
            ``lambda p: torch.save(obj, p)``).
    """
    with atomic_target(path) as tmp:  # the data layer's one temp-then-rename helper
        if isinstance(write, str):
            tmp.write_text(write)
        else:
            write(tmp)
    return Path(path)


def read_json(path: str | os.PathLike[str]) -> Any:
    """A JSON file of a run folder.

    Raises:
        RunFolderError: The file is not valid JSON (the message names it).
    """
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RunFolderError(f"{path} is damaged ({exc}); delete it to redo that step") from None


def config_differences(run_dir: str | os.PathLike[str], config: dict[str, Any]) -> list[str]:
    """Settings in which the folder's ``config.json`` differs from ``config`` (runtime
    settings aside; both read as :func:`abco_train.methods.registry.identity` reads them, so
    a folder written before a setting moved into the method's options still matches); empty
    when they agree or the folder has no config yet."""
    path = Path(run_dir) / CONFIG
    if not path.exists():
        return []
    had, wanted = identity(read_json(path)), identity(config)
    return sorted(k for k in set(had) | set(wanted) if had.get(k) != wanted.get(k))


def finished_result(run_dir: str | os.PathLike[str], config: dict[str, Any]
                    ) -> dict[str, Any] | None:  # fmt: skip
    """The stored ``final.json`` of a finished run of this very config, else ``None``."""
    final = Path(run_dir) / FINAL
    if not final.exists() or config_differences(run_dir, config):
        return None
    return read_json(final)

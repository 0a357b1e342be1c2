"""A run's checkpoint: everything needed to resume after an iteration.

``checkpoint.pt`` holds the iteration, the method's state (:meth:`Method.state_dict`), its
interaction counts, torch's generator states and the run's config. It is written whole or not
at all (:func:`abco_train.harness.run_folder.write_atomic`).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from abco_train.config.run import RunConfig
from abco_train.harness.run_folder import RunFolderError, write_atomic
from abco_train.methods.base import Method

__all__ = ["save_checkpoint", "load_checkpoint", "restore"]


def save_checkpoint(path: Path, iteration: int, method: Method, cfg: RunConfig) -> None:
    """Write the state after ``iteration`` to ``path``."""
    payload = {"iteration": iteration, "method": method.state_dict(),
               "interactions": dict(method.interactions),
               "torch_rng": torch.get_rng_state(), "config": asdict(cfg),
               "cuda_rng": torch.cuda.get_rng_state_all() if cfg.device.startswith("cuda")
               else None}  # fmt: skip
    write_atomic(path, lambda tmp: torch.save(payload, tmp))


def load_checkpoint(path: Path, device: str) -> dict[str, Any] | None:
    """The checkpoint's state on ``device`` (a GPU run resumes on CPU), ``None`` without one.

    Raises:
        RunFolderError: The checkpoint is damaged (e.g. truncated).
    """
    if not path.exists():
        return None
    try:
        return torch.load(path, map_location=device, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise RunFolderError(f"{path} is damaged ({type(exc).__name__}: {exc}); delete it to "
                             "restart the run") from None  # fmt: skip


def restore(method: Method, state: dict[str, Any], cfg: RunConfig) -> int:
    """Put ``state`` back into ``method`` and torch's generators; the next iteration."""
    method.load_state_dict(state["method"])
    method.interactions.update(state.get("interactions", {}))
    torch.set_rng_state(state["torch_rng"].cpu())
    if state.get("cuda_rng") is not None and cfg.device.startswith("cuda"):
        torch.cuda.set_rng_state_all([x.cpu() for x in state["cuda_rng"]])
    return int(state["iteration"]) + 1

"""Supervised fitting shared by the BCO family's two networks: minibatch cross-entropy epochs,
batched predictions, the transposed-maze augmentation and the IDM's fixed held-out split."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from abco_train.harness.runtime import derived_rng

__all__ = ["fit", "predict", "transpose_batch", "validation_split", "TRANSPOSED_ACTIONS",
           "VALIDATION_CAP"]  # fmt: skip

#: A maze transposed about its main diagonal ((row, col) -> (col, row); start and goal stay)
#: turns each action into another: N <-> W, S <-> E (``abco_envs.Action`` order N, S, E, W).
TRANSPOSED_ACTIONS = torch.tensor([3, 2, 1, 0])

#: Held out of ``I_pre`` by default: 10% of it, at most this many transitions.
VALIDATION_CAP = 2_000
#: The held-out split's own stream (:func:`abco_train.harness.runtime.derived_rng`).
VALIDATION_TAG = 0x1D


def transpose_batch(frames: list[torch.Tensor], labels: torch.Tensor, rng: np.random.Generator
                    ) -> tuple[list[torch.Tensor], torch.Tensor]:  # fmt: skip
    """Transpose each example of a minibatch with probability 1/2 (``--augment transpose``).

    A chosen example's ``(B, H, W, C)`` frames (all of them: ``s`` and ``s'`` of a transition)
    are transposed about the main diagonal and its action label mapped by
    :data:`TRANSPOSED_ACTIONS`: a transposed maze, rendered, is the transposed frame, and its
    start ``(0, 0)`` and goal ``(n-1, n-1)`` stay where they are.
    """
    flip = torch.from_numpy(rng.random(len(labels)) < 0.5)
    if not flip.any():
        return frames, labels
    out = []
    for x in frames:
        x = x.clone()
        x[flip] = x[flip].transpose(1, 2)
        out.append(x)
    labels = labels.clone()
    labels[flip] = TRANSPOSED_ACTIONS.to(labels.device)[labels[flip]]
    return out, labels


def fit(
    net: torch.nn.Module,
    opt: torch.optim.Optimizer,
    inputs: Any,
    labels: torch.Tensor,
    epochs: int,
    batch_size: int,
    rng: np.random.Generator,
    desc: str = "",
    quiet: bool = True,
    device: torch.device | None = None,
    augment: bool = False,
    max_batches: int | None = None,
) -> float:
    """Cross-entropy epochs over ``labels``; ``inputs(idx) -> args of net`` (tensors on
    ``device`` already, or moved there batch by batch); ``augment``: :func:`transpose_batch` on each
    minibatch; ``max_batches``: stop after that many updates. Mean loss of the last epoch."""
    from tqdm.auto import tqdm

    from abco_data.progress import is_terminal

    net.train()
    n, seen = len(labels), 0
    batches = -(-n // batch_size)
    total = epochs * batches if max_batches is None else min(epochs * batches, max_batches)
    # minibatch bars only on a terminal: in a log they would repeat for every epoch
    bar = tqdm(total=total, desc=desc, leave=False, disable=quiet or not is_terminal(sys.stderr),
               unit="batch")  # fmt: skip
    done = 0  # not bar.n: a disabled bar counts nothing
    # The loss is summed where it is computed (in float64, as Python floats would be): no
    # host synchronisation per minibatch on a GPU, one per epoch.
    total_loss = torch.zeros((), dtype=torch.float64, device=device)
    for _ in range(epochs):
        order = torch.from_numpy(rng.permutation(n))
        total_loss, seen = torch.zeros((), dtype=torch.float64, device=device), 0
        for start in range(0, n, batch_size):
            if done >= total:
                break
            bar.update(1)
            done += 1
            idx = order[start : start + batch_size]
            batch, targets = list(inputs(idx)), labels[idx]
            if augment:
                batch, targets = transpose_batch(batch, targets, rng)
            batch = [x.to(device, non_blocking=True) for x in batch]
            loss = F.cross_entropy(net(*batch), targets.to(device, non_blocking=True))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total_loss, seen = total_loss + loss.detach().double() * len(idx), seen + len(idx)
    bar.close()
    return float(total_loss) / max(seen, 1)


@torch.no_grad()
def predict(net: torch.nn.Module, inputs: Any, n: int, batch_size: int = 512,
             device: torch.device | None = None) -> torch.Tensor:  # fmt: skip
    """Argmax predictions of ``net`` over ``n`` rows, in batches (on CPU)."""
    net.eval()
    out = [
        net(*[x.to(device) for x in inputs(torch.arange(s, min(s + batch_size, n)))]).argmax(1)
        .cpu() for s in range(0, n, batch_size)
    ]  # fmt: skip
    return torch.cat(out) if out else torch.zeros(0, dtype=torch.long)


def validation_split(n: int, size: int | None, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(train, held-out)`` indices of ``n`` pre-demonstration transitions.

    The held-out part has ``size`` transitions (default 10%, at most :data:`VALIDATION_CAP`),
    drawn by a generator of its own, so the split is fixed by the seed and moves none of the
    run's other draws.

    Example:
        >>> train, held = validation_split(100, None, seed=0)
        >>> len(train), len(held), len(set(train) & set(held))
        (90, 10, 0)
    """
    size = min(n - 1, size if size is not None else min(VALIDATION_CAP, max(1, n // 10)))
    order = derived_rng(seed, VALIDATION_TAG).permutation(n)
    return np.sort(order[size:]), np.sort(order[:size])

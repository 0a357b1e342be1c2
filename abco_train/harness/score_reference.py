"""The references of the normalised score, measured the way each evaluation is run.

An episode's score is ``(R - R_random) / (R_expert - R_random)``: 0 is a uniform random
policy, 1 the expert, both under the *same* protocol as the episode, on the same layouts and
start (mazes) or the same environment (other envs), from reference seeds of their own.

- Mazes: per layout, :func:`abco_data.protocol_reference` (random walks under the block's
  protocol, ``paper`` or ``standard``, and step cap; the expert's shortest path).
- Other envs: the expert dataset's references (its expert and uniform random actions over
  seeded episodes under the env's rules), which are the evaluation's protocol unless
  ``eval_max_steps`` caps the episodes; then :func:`abco_data.classic_reference` with that cap.

The paper's ``P`` keeps its own references (the dataset's, under the env's 1000-step rules,
whatever the protocol), as the authors computed it.
"""

from __future__ import annotations

import numpy as np

import abco_data
import abco_envs
from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData

__all__ = ["score_reference", "layout_cells"]


def layout_cells(cfg: RunConfig, data: TrainingData, split: str,
                 layouts: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """The ``(k, n, n)`` layouts an evaluation of ``split`` plays (mazes): ``layouts`` if
    given, a run's training layouts for ``train`` on procedural data, else the pool's split;
    the first ``eval_layouts`` of them."""
    from abco_envs.maze.pool import layout_pool

    if layouts is None:
        layouts = data.train_layouts if split == "train" else None
    if layouts is None:
        layouts = np.asarray(layout_pool(abco_envs.maze_size(cfg.env)).split(split))
    return np.asarray(layouts)[: cfg.eval_layouts] if cfg.eval_layouts else np.asarray(layouts)


def score_reference(cfg: RunConfig, data: TrainingData, protocol: str,
                    cells: np.ndarray | None = None) -> abco_data.ReferenceReturns:  # fmt: skip
    """The score's references of an evaluation under ``protocol`` (mazes: on ``cells``)."""
    if data.is_maze:
        if cells is None:
            raise ValueError("a maze evaluation's score needs its layouts")
        return abco_data.protocol_reference(cells, protocol, cfg.eval_max_steps)
    if cfg.eval_max_steps is None:
        return data.reference
    from abco_data.generation.reference import classic_reference

    return classic_reference(cfg.env, max_steps=cfg.eval_max_steps)

"""The bounds of every creation parameter, checked before generation allocates anything.

A ``--set`` override (or a keyword of :func:`abco_data.generate`) is refused, in one line
naming the parameter, its value and its range, when it is of the wrong type or beyond its
bound. The bounds come from what a value would cost, and leave room for real use:

- each count has its own range (:data:`COUNT_BOUNDS`); ``layouts`` runs from 1 to the
  layouts of the dataset's split (100 for ``train``, 10,000 for ``procedural``), and
  ``image_size`` from 2 pixels a cell to :data:`~abco_envs.maze.options.MAX_IMAGE_SIDE`;
- classic control: ``transitions``, and ``episodes`` times the env's step limit, at most
  :data:`MAX_TRANSITIONS`;
- mazes: the frames a dataset can hold (episodes times their longest length plus one),
  times a frame's bytes, at most :data:`MAX_FRAME_BYTES` of raw frames (the standard
  datasets take at most about 12 GB: 10,000 10x10 procedural layouts);
- ``seed`` is an integer from 0 to :data:`MAX_SEED`; flags are ``true`` or ``false``.

Example:
    >>> check_params("abco/cartpole-pre-v0", "CartPole-v1", "pre_demonstrations",
    ...              {"transitions": -1})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    abco_data.errors.InvalidParameterError: abco/cartpole-pre-v0: transitions=-1 is out of ...
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

import abco_envs
from abco_data.errors import InvalidParameterError
from abco_envs.maze.options import MAX_IMAGE_SIDE
from abco_envs.maze.pool import SPLIT_SIZE
from abco_envs.maze.procedural import PROCEDURAL_SPLIT_SIZE
from abco_envs.maze.rules import MAX_EPISODE_STEPS

__all__ = ["COUNT_BOUNDS", "FLAGS", "MAX_FRAME_BYTES", "MAX_SEED", "MAX_TRANSITIONS",
           "SPLIT_LAYOUTS", "check_params"]

#: Most transitions of a classic-control dataset (about 50 bytes each, a few minutes).
MAX_TRANSITIONS = 10_000_000
#: Most raw frame bytes a maze dataset may hold (stored palette-encoded and compressed, the
#: file is a small part of this).
MAX_FRAME_BYTES = 32 << 30
#: Largest ``seed``: episode seeds ``seed + i`` stay well inside int64.
MAX_SEED = 2**62
#: Layouts of each split a dataset may be made from.
SPLIT_LAYOUTS = {"train": SPLIT_SIZE, "procedural": PROCEDURAL_SPLIT_SIZE}
#: ``name -> (lowest, highest)`` of the plain counts.
COUNT_BOUNDS: Mapping[str, tuple[int, int]] = {
    "solutions_per_layout": (1, 1_000),
    "episodes_per_layout": (1, 10_000),
    "max_steps": (1, MAX_EPISODE_STEPS),
    "reference_episodes": (1, 10_000),
    "reference_expert_episodes": (1, 10_000),
    "episodes": (1, 100_000),
    "transitions": (1, MAX_TRANSITIONS),
}
#: Parameters that are ``true`` or ``false``.
FLAGS = ("drop_wall_hits", "from_start_cell")
_MAX_HOLD = 1_000


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _check_int(dataset_id: str, name: str, value: Any, lo: int, hi: int, why: str = "") -> int:
    if not _is_int(value):
        raise InvalidParameterError(f"{dataset_id}: {name} must be an integer from {lo} to"
                                    f" {hi}, got {value!r} ({type(value).__name__})")
    if not lo <= value <= hi:
        raise InvalidParameterError(f"{dataset_id}: {name}={value!r} is out of range: from"
                                    f" {lo} to {hi}{why}")
    return int(value)


def _image_side(dataset_id: str, value: Any, size: int) -> tuple[int, int]:
    pair = value if isinstance(value, (list, tuple)) and len(value) == 2 else (value, value)
    least = 2 * size
    why = f" (2 pixels a cell of the {size}x{size} maze, at most {MAX_IMAGE_SIDE} a side)"
    h, w = (_check_int(dataset_id, "image_size", v, least, MAX_IMAGE_SIDE, why) for v in pair)
    return h, w


def _check_hold(dataset_id: str, value: Any) -> None:
    if isinstance(value, (list, tuple)) and len(value) == 2:
        lo = _check_int(dataset_id, "hold[0]", value[0], 1, _MAX_HOLD)
        _check_int(dataset_id, "hold[1]", value[1], lo, _MAX_HOLD)
    else:
        _check_int(dataset_id, "hold", value, 1, _MAX_HOLD)


def _check_maze_total(dataset_id: str, env_id: str, kind: str, p: Mapping[str, Any]) -> None:
    """The frames the dataset can hold, times a frame's bytes, within MAX_FRAME_BYTES."""
    size = abco_envs.maze_size(env_id)
    h, w = _image_side(dataset_id, p["image_size"], size)
    if kind == "expert":
        episodes, longest = p["layouts"] * p["solutions_per_layout"], size * size - 1
    else:
        episodes, longest = p["layouts"] * p["episodes_per_layout"], p["max_steps"]
    frames = episodes * (longest + 1)
    if frames * h * w * 3 > MAX_FRAME_BYTES:
        raise InvalidParameterError(
            f"{dataset_id}: {episodes} episodes of up to {longest} steps of {h}x{w} frames"
            f" could hold {frames * h * w * 3 / 2**30:,.0f} GiB of frames, more than the"
            f" {MAX_FRAME_BYTES >> 30} GiB a dataset may: fewer layouts, episodes or pixels")


def check_params(dataset_id: str, env_id: str, kind: str, params: Mapping[str, Any]) -> None:
    """Check every creation parameter of a dataset against its bounds (see the module).

    Args:
        dataset_id: The dataset, for the messages.
        env_id: Its environment.
        kind: ``"expert"`` or ``"pre_demonstrations"``.
        params: Its creation parameters, overrides applied.

    Raises:
        InvalidParameterError: A parameter of the wrong type or beyond its bound.
    """
    for name, value in params.items():
        if name in COUNT_BOUNDS:
            _check_int(dataset_id, name, value, *COUNT_BOUNDS[name])
        elif name in FLAGS and not isinstance(value, bool):
            raise InvalidParameterError(f"{dataset_id}: {name} must be true or false, got"
                                        f" {value!r}")
    _check_int(dataset_id, "seed", params.get("seed", 0), 0, MAX_SEED)
    if "hold" in params:
        _check_hold(dataset_id, params["hold"])
    if abco_envs.is_maze(env_id):
        split = params.get("split", "train")
        layouts = SPLIT_LAYOUTS.get(split, SPLIT_SIZE)
        _check_int(dataset_id, "layouts", params["layouts"], 1, layouts,
                   f" (the layouts of the {split!r} split)")
        _check_maze_total(dataset_id, env_id, kind, params)
    elif kind == "expert":
        steps = gym.spec(env_id).max_episode_steps or MAX_TRANSITIONS
        _check_int(dataset_id, "episodes", params["episodes"], 1, MAX_TRANSITIONS // steps,
                   f" ({steps}-step episodes, at most {MAX_TRANSITIONS:,} transitions)")

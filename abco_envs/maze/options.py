"""The maze envs' inputs, checked in one place for both the single and the vector env.

Every check raises the package's own errors (:mod:`abco_envs.errors`), naming the argument,
option or action and the bad value. Integers are Python ``int`` or numpy integers (0-d integer
arrays too); ``bool`` is refused everywhere, because ``True`` passed as an action or a cell is
almost always a mistake (a ``terminated`` flag, a mask) rather than the number 1. Floats are
refused rather than truncated, and strings rather than parsed.

Example:
    >>> resolve_image_size(64)
    (64, 64)
    >>> check_action(2)
    2
    >>> check_start((1, 2), size=5)
    (1, 2)
    >>> check_env_options(5, "pixels", "train")
    Traceback (most recent call last):
    ...
    abco_envs.errors.InvalidOptionError: unknown obs_type 'pixels'; expected one of ('image', 'state')
"""  # noqa: E501

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, TypeGuard

import numpy as np

from abco_envs.errors import InvalidActionError, InvalidOptionError, OptionOutOfRangeError
from abco_envs.maze.observation import OBS_TYPES
from abco_envs.maze.pool import SPLITS
from abco_envs.maze.procedural import MIN_FRESH_SIZE, MIN_PROCEDURAL_SIZE
from abco_envs.maze.rules import START_POSITION, Action, goal_position

__all__ = [
    "LAYOUT_SOURCES",
    "MAX_IMAGE_SIDE",
    "MAX_MAZE_SIZE",
    "MAX_NUM_ENVS",
    "MAX_VECTOR_BYTES",
    "RESET_OPTIONS",
    "check_action",
    "check_actions",
    "check_env_options",
    "check_layout_index",
    "check_num_envs",
    "check_render_mode",
    "check_reset_options",
    "check_start",
    "is_integer",
    "resolve_image_size",
]

#: The values of the ``split`` argument: the pool's splits, the procedural split (the
#: procedural datasets' layouts), or fresh layouts (in no split and no dataset).
LAYOUT_SOURCES = (*SPLITS, "procedural", "fresh")
#: Smallest maze of each split beyond the pool (small grids have too few layouts).
_MIN_SIZE = {"procedural": MIN_PROCEDURAL_SIZE, "fresh": MIN_FRESH_SIZE}
#: Largest ``image_size`` side, in pixels (a 4096x4096 frame takes 48 MiB).
MAX_IMAGE_SIDE = 4096
#: Largest maze, in cells a side (drawing a split's layouts grows fast with the size: about
#: 25 s for 200 layouts of 50x50).
MAX_MAZE_SIZE = 64
#: Most mazes in one :class:`~abco_envs.maze.vector.MazeVectorEnv`.
MAX_NUM_ENVS = 65_536
#: Most memory a vector env's per-maze arrays may take (frames, backgrounds, move tables).
MAX_VECTOR_BYTES = 16 << 30
#: The keys a maze env's ``reset(options=...)`` understands.
RESET_OPTIONS = ("layout", "layout_index", "start")

_ACTIONS_TEXT = "0 (N), 1 (S), 2 (E) or 3 (W)"
_N_ACTIONS = len(Action)  # len() of an Enum class is a slow Python-level call: once, here
# The types an action usually comes as: one set look-up keeps the single env's step cheap.
_PLAIN_INTEGER_TYPES = frozenset(
    {int, np.int64, np.int32, np.int16, np.int8, np.uint64, np.uint32, np.uint16, np.uint8}
)


def is_integer(value: Any) -> TypeGuard[int | np.integer[Any] | np.ndarray]:
    """True for a Python or numpy integer (or a 0-d integer array); False for ``bool``.

    Example:
        >>> [is_integer(v) for v in (3, np.int8(3), np.array(3), True, 3.0, "3")]
        [True, True, True, False, False, False]
    """
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, (int, np.integer)):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu"


def _describe(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def check_env_options(size: Any, obs_type: Any, split: Any) -> None:
    """Check the arguments every maze env takes.

    Raises:
        InvalidOptionError: An unknown ``obs_type`` or ``split``, a ``size`` that is not an
            integer from 2 to :data:`MAX_MAZE_SIZE`, or a maze too small for the
            ``procedural`` or ``fresh`` split.
    """
    if obs_type not in OBS_TYPES:
        raise InvalidOptionError(f"unknown obs_type {obs_type!r}; expected one of {OBS_TYPES}")
    if split not in LAYOUT_SOURCES:
        raise InvalidOptionError(f"unknown split {split!r}; expected one of {LAYOUT_SOURCES}")
    if not is_integer(size) or not 2 <= size <= MAX_MAZE_SIZE:
        raise InvalidOptionError(
            f"a maze needs an integer size from 2 to {MAX_MAZE_SIZE} cells,"
            f" got size={_describe(size)}"
        )
    least = _MIN_SIZE.get(split, 2)
    if size < least:
        raise InvalidOptionError(
            f"split={split!r} needs a maze of at least {least}x{least} cells, got {size}x{size}"
            " (a smaller grid has too few layouts outside the canonical pool)"
        )


def check_render_mode(render_mode: Any, render_modes: Sequence[str]) -> None:
    """``render_mode`` is ``None`` or one of ``render_modes``, else InvalidOptionError."""
    if render_mode is not None and render_mode not in render_modes:
        raise InvalidOptionError(
            f"unknown render_mode {render_mode!r}; expected one of {list(render_modes)}"
        )


def _is_integer_pair(value: Any) -> bool:
    """A tuple, list or 1-d array of two integers."""
    sequence = isinstance(value, (tuple, list)) or (
        isinstance(value, np.ndarray) and value.ndim == 1
    )
    return sequence and len(value) == 2 and all(is_integer(v) for v in value)


def resolve_image_size(image_size: Any, size: int | None = None) -> tuple[int, int]:
    """``64`` -> ``(64, 64)``; ``(h, w)`` stays as it is.

    Args:
        image_size: One integer, or a ``(height, width)`` pair of integers.
        size: The maze's cells per side, to check for at least 2 pixels per cell.

    Raises:
        InvalidOptionError: Anything else (a string, a pair of floats, a wrong length), a
            size below 1 pixel, fewer than 2 pixels per cell, or a side above
            :data:`MAX_IMAGE_SIDE` (checked before anything is drawn).
    """
    if is_integer(image_size):
        height = width = int(image_size)
    elif _is_integer_pair(image_size):
        height, width = (int(v) for v in image_size)
    else:
        raise InvalidOptionError(
            "image_size must be an integer or a (height, width) pair of integers,"
            f" got {_describe(image_size)}"
        )
    least = 1 if size is None else 2 * size
    if height < least or width < least:
        raise InvalidOptionError(
            f"image_size {image_size!r} is too small"
            + ("" if size is None else f" for a {size}x{size} maze: at least 2 pixels per cell"
               f" are needed ({least}x{least})")
        )
    if height > MAX_IMAGE_SIDE or width > MAX_IMAGE_SIDE:
        raise InvalidOptionError(
            f"image_size {image_size!r} is too large: at most {MAX_IMAGE_SIDE} pixels a side"
            f" (a {height}x{width} frame would take {height * width * 3 / 2**20:,.0f} MiB)"
        )
    return height, width


def check_num_envs(num_envs: Any, size: int, height: int, width: int) -> int:
    """The ``num_envs`` of a vector env, checked against what its mazes would take.

    Each maze keeps a frame-sized background and its share of the observation batch (and of
    the batched space's bounds), plus move and wall tables of its cells.

    Raises:
        InvalidOptionError: Not an integer from 1 to :data:`MAX_NUM_ENVS`, or mazes that
            would take more than :data:`MAX_VECTOR_BYTES` together.
    """
    if not is_integer(num_envs) or not 1 <= num_envs <= MAX_NUM_ENVS:
        raise InvalidOptionError(
            f"num_envs must be an integer from 1 to {MAX_NUM_ENVS}, got {_describe(num_envs)}"
        )
    per_maze = 4 * height * width * 3 + 64 * size * size
    if int(num_envs) * per_maze > MAX_VECTOR_BYTES:
        raise InvalidOptionError(
            f"num_envs={int(num_envs)} mazes of {height}x{width} frames would take about"
            f" {int(num_envs) * per_maze / 2**30:,.1f} GiB (at most {MAX_VECTOR_BYTES >> 30}"
            f" GiB): use at most {MAX_VECTOR_BYTES // per_maze} of them, or smaller frames"
        )
    return int(num_envs)


def check_action(action: Any) -> int:
    """One maze's action as an int in ``0..3``.

    Raises:
        InvalidActionError: Not an integer (floats, strings, ``None``, ``bool``), or out of
            range.
    """
    # The usual types are found by one set look-up, before the slower full check.
    if type(action) not in _PLAIN_INTEGER_TYPES and not is_integer(action):
        raise InvalidActionError(
            f"invalid action {_describe(action)}: expected an integer {_ACTIONS_TEXT}"
        )
    a = int(action)
    if not 0 <= a < _N_ACTIONS:
        raise InvalidActionError(f"invalid action {action!r}: expected {_ACTIONS_TEXT}")
    return a


def check_actions(actions: Any, num_envs: int) -> np.ndarray:
    """One action per maze, as an ``int64`` array of shape ``(num_envs,)``.

    Raises:
        InvalidActionError: Not integers (a float, bool, string or object array), not
            ``num_envs`` of them, or any out of range.
    """
    arr = np.asarray(actions)
    if arr.dtype.kind not in "iu":
        raise InvalidActionError(
            f"invalid actions {actions!r}: expected integers {_ACTIONS_TEXT}, one per maze,"
            f" got dtype {arr.dtype}"
        )
    arr = arr.astype(np.int64, copy=False).reshape(-1)
    if arr.shape != (num_envs,):
        raise InvalidActionError(f"expected {num_envs} actions, got shape {np.shape(actions)}")
    if arr.min() < 0 or arr.max() >= _N_ACTIONS:
        bad = np.flatnonzero((arr < 0) | (arr >= _N_ACTIONS))
        raise InvalidActionError(
            f"invalid action {arr[bad[0]]} for maze {bad[0]} ({len(bad)} bad in all):"
            f" expected {_ACTIONS_TEXT} per maze"
        )
    return arr


def check_reset_options(options: Any) -> Mapping[str, Any]:
    """The ``options`` of a reset: ``None`` or a dict whose keys are in :data:`RESET_OPTIONS`.

    Raises:
        InvalidOptionError: Not a dict, or an unknown key (a typo would otherwise be ignored).
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise InvalidOptionError(
            f"reset options must be a dict with keys among {RESET_OPTIONS},"
            f" got {_describe(options)}"
        )
    unknown = sorted(str(k) for k in options if k not in RESET_OPTIONS)
    if unknown:
        raise InvalidOptionError(
            f"unknown reset option(s) {', '.join(map(repr, unknown))};"
            f" expected keys among {RESET_OPTIONS}"
        )
    return options


def check_layout_index(index: Any, count: int, split: str) -> int:
    """The ``layout_index`` reset option as an int in ``0..count - 1``.

    Raises:
        InvalidOptionError: Not an integer.
        OptionOutOfRangeError: Outside the split (also an ``IndexError``).
    """
    if not is_integer(index):
        raise InvalidOptionError(
            f"reset option 'layout_index' must be an integer, got {_describe(index)}"
        )
    index = int(index)
    if not 0 <= index < count:
        raise OptionOutOfRangeError(
            f"reset option 'layout_index' {index} is out of range for the {split!r} split"
            f" of {count} layouts"
        )
    return index


def check_start(start: Any, size: int) -> tuple[int, int]:
    """The ``start`` reset option as a ``(row, col)`` cell; ``None`` gives the usual start.

    Raises:
        InvalidOptionError: Not a pair of integers, or the goal cell (an episode cannot start
            where it ends).
        OptionOutOfRangeError: Outside the ``size`` x ``size`` maze (also an ``IndexError``).
    """
    if start is None:
        return START_POSITION
    try:
        row, col = start
    except (TypeError, ValueError):
        row = col = None
    if isinstance(start, (str, bytes)) or not (is_integer(row) and is_integer(col)):
        raise InvalidOptionError(
            f"reset option 'start' must be a (row, col) pair of integers, got {_describe(start)}"
        )
    row, col = int(row), int(col)
    if not (0 <= row < size and 0 <= col < size):
        raise OptionOutOfRangeError(
            f"reset option 'start' {start!r} is outside the {size}x{size} maze"
        )
    if (row, col) == goal_position(size):
        raise InvalidOptionError(
            f"reset option 'start' {start!r} is the goal of the {size}x{size} maze:"
            " an episode cannot start where it ends"
        )
    return row, col

"""A native batched maze: all mazes step in one numpy call.

Reached with ``gym.make_vec("AbcoMaze5x5-v0", num_envs=256,
vectorization_mode="vector_entry_point")``. It equals ``SyncVectorEnv`` over
:class:`~abco_envs.maze.env.MazeEnv` step for step: the same per-env seeds (``seed + i``), the
same layout draws, next-step autoreset, and the same ``info`` keys with their ``_key`` masks.

Frames are cheap: each maze keeps its background (walls, start, goal; redrawn only on reset),
and a step copies all backgrounds at once and writes every agent's dot with one flat
fancy-index assignment, whose byte offsets are precomputed per cell.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from abco_envs.errors import InvalidOptionError
from abco_envs.maze.observation import (
    image_observation_space,
    state_features,
    state_observation_space,
)
from abco_envs.maze.options import (
    check_actions,
    check_env_options,
    check_num_envs,
    check_render_mode,
    check_reset_options,
    check_start,
    is_integer,
    resolve_image_size,
)
from abco_envs.maze.pool import SPLITS
from abco_envs.maze.render import MazeRenderer
from abco_envs.maze.reset import DrawnLayout, LayoutSource
from abco_envs.maze.rules import MAX_EPISODE_STEPS, START_POSITION, MazeDynamics

__all__ = ["MazeVectorEnv"]


def _per_env(value: Any, num_envs: int, single_ndim: int, name: str) -> list[Any]:
    """A reset option given once for all mazes, or once per maze (one more leading axis).

    A value with fewer axes than one maze's counts as given once: the option's own check
    then says what is wrong with it.
    """
    if value is None:
        return [None] * num_envs
    try:
        ndim = np.ndim(value)
    except ValueError:  # a ragged nest of sequences
        ndim = -1
    if 0 <= ndim <= single_ndim:
        return [value] * num_envs
    if ndim == single_ndim + 1 and len(value) == num_envs:
        return list(value)
    raise InvalidOptionError(
        f"reset option {name!r} must be given once or once per maze ({num_envs} values),"
        f" got {value!r}"
    )


class MazeVectorEnv(VectorEnv):
    """``num_envs`` mazes of one size stepped together (see :class:`MazeEnv` for the rules).

    Reset options may be given per maze: ``layout_index`` and ``start`` as sequences of
    ``num_envs`` values, ``layout`` as an ``(num_envs, n, n)`` array.

    Example:
        >>> import gymnasium as gym
        >>> import abco_envs
        >>> envs = gym.make_vec(
        ...     "AbcoMaze3x3-v0", num_envs=4, vectorization_mode="vector_entry_point"
        ... )
        >>> obs, info = envs.reset(seed=0)
        >>> obs.shape
        (4, 64, 64, 3)
        >>> obs, rewards, terminated, truncated, info = envs.step(envs.action_space.sample())
        >>> envs.close()
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        size: int = 5,
        obs_type: str = "image",
        image_size: int | tuple[int, int] = 64,
        split: str = "train",
        max_episode_steps: int | None = MAX_EPISODE_STEPS,
        render_mode: str | None = None,
    ) -> None:
        check_env_options(size, obs_type, split)
        check_render_mode(render_mode, self.metadata["render_modes"])
        height, width = resolve_image_size(image_size, size)
        num_envs = check_num_envs(num_envs, size, height, width)  # before any allocation
        if max_episode_steps is not None and (not is_integer(max_episode_steps)
                                              or max_episode_steps < 1):
            raise InvalidOptionError(
                f"max_episode_steps must be None or an integer of at least 1,"
                f" got {max_episode_steps!r}"
            )
        num_envs, size = int(num_envs), int(size)
        self.num_envs, self.size, self.obs_type, self.split = num_envs, size, obs_type, split
        self.render_mode = render_mode
        self.max_episode_steps = max_episode_steps if max_episode_steps is not None else np.inf
        self.renderer = MazeRenderer(size, height, width)
        self.single_action_space = spaces.Discrete(4)
        self.action_space = batch_space(self.single_action_space, num_envs)
        if obs_type == "image":
            self.single_observation_space = image_observation_space(
                self.renderer.height, self.renderer.width
            )
        else:
            self.single_observation_space = state_observation_space(size)
        self.observation_space = batch_space(self.single_observation_space, num_envs)

        self._layouts = LayoutSource(size, split)
        self._dynamics = MazeDynamics(size)
        self._pool_backgrounds: dict[int, np.ndarray] = {}
        n, h, w = size, self.renderer.height, self.renderer.width
        self._rngs = [seeding.np_random()[0] for _ in range(num_envs)]
        self.cells = np.zeros((num_envs, n, n), dtype=np.uint8)
        self.positions = np.zeros((num_envs, 2), dtype=np.int64)
        self._cell = np.zeros(num_envs, dtype=np.intp)  # row-major, what the kernel steps
        self._moves = np.zeros((num_envs, n * n, 4), dtype=np.intp)
        self.layout_ids = np.full(num_envs, None, dtype=object)
        self.layout_indices = np.full(num_envs, -1, dtype=np.int64)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._backgrounds = np.zeros((num_envs, h, w, 3), dtype=np.uint8)
        self._frame_bytes = h * w * 3
        self._walls = np.zeros((num_envs, 4 * n * n), dtype=np.float32)
        self._arange = np.arange(num_envs)

    # -- resets -------------------------------------------------------------------------------

    def _background(self, index: int, cells: np.ndarray) -> np.ndarray:
        # Only the pool's 100-layout splits are cached: the procedural split's 10,000
        # backgrounds would take 120 MB at 64x64 (1.5 GB at 224x224).
        if index < 0 or self.split not in SPLITS:
            return self.renderer.background(cells)
        if index not in self._pool_backgrounds:
            self._pool_backgrounds[index] = self.renderer.background(cells)
        return self._pool_backgrounds[index]

    def _reset_one(
        self, i: int, drawn: DrawnLayout | None = None, start: tuple[int, int] = START_POSITION
    ) -> None:
        """Reset maze ``i`` exactly as ``MazeEnv.reset`` would (same draws from its rng)."""
        if drawn is None:
            drawn = self._layouts.draw(self._rngs[i])
        row, col = start
        self.cells[i] = drawn.cells
        self._moves[i] = drawn.moves
        self.layout_indices[i], self.layout_ids[i] = drawn.index, drawn.layout_id
        self.positions[i] = row, col
        self._cell[i] = row * self.size + col
        self._steps[i] = 0
        self._walls[i] = state_features(drawn.cells)
        self._backgrounds[i] = self._background(drawn.index, drawn.cells)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every maze; an int ``seed`` seeds maze ``i`` with ``seed + i``."""
        # The base class seeds its own generator (unused here) from an int seed only.
        super().reset(seed=seed if isinstance(seed, int) else None)
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
            if len(seeds) != self.num_envs:
                raise ValueError(f"expected {self.num_envs} seeds, got {len(seeds)}")
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        checked = check_reset_options(options)
        layouts = _per_env(checked.get("layout"), self.num_envs, 2, "layout")
        indices = _per_env(checked.get("layout_index"), self.num_envs, 0, "layout_index")
        # Every option is checked (and every layout drawn) before any maze resets, so a bad
        # value for one maze leaves all of them as they were.
        starts = [check_start(s, self.size)
                  for s in _per_env(checked.get("start"), self.num_envs, 1, "start")]
        drawn = [self._layouts.draw(rng, layout, index)
                 for rng, layout, index in zip(self._rngs, layouts, indices)]
        for i in range(self.num_envs):
            self._reset_one(i, drawn[i], starts[i])
        self._needs_reset[:] = False
        return self._observe(), self._infos(reset=np.ones(self.num_envs, dtype=bool))

    # -- stepping -----------------------------------------------------------------------------

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every maze; a maze that ended on the last step is reset instead (next-step)."""
        actions = check_actions(actions, self.num_envs)
        resetting = self._needs_reset.copy()
        for i in np.flatnonzero(resetting):
            self._reset_one(int(i))
        active = ~resetting

        next_cell, rewards, at_goal = self._dynamics.step(
            self._moves, self._arange, self._cell, actions
        )
        if resetting.any():  # a maze that resets this step stays on its start
            next_cell[resetting] = self._cell[resetting]
            rewards[resetting] = 0.0
        self._cell = next_cell
        self.positions[:, 0], self.positions[:, 1] = np.divmod(next_cell, self.size)
        self._steps[active] += 1

        terminated = active & at_goal
        truncated = active & (self._steps >= self.max_episode_steps)
        self._needs_reset = terminated | truncated
        return self._observe(), rewards, terminated, truncated, self._infos(resetting)

    def _frames(self) -> np.ndarray:
        """Fresh frames of every maze: the backgrounds plus each agent's dot."""
        frames = self._backgrounds.copy()
        offsets = self.renderer.dot_bytes[self._cell] + (self._arange * self._frame_bytes)[:, None]
        frames.reshape(-1)[offsets.ravel()] = np.broadcast_to(
            self.renderer.dot_colour, offsets.shape
        ).ravel()
        return frames

    def _observe(self) -> np.ndarray:
        if self.obs_type == "image":
            return self._frames()
        n = self.size
        obs = np.zeros((self.num_envs, 2 * n + 4 * n * n), dtype=np.float32)
        obs[self._arange, self.positions[:, 0]] = 1.0
        obs[self._arange, n + self.positions[:, 1]] = 1.0
        obs[:, 2 * n :] = self._walls
        return obs

    def _infos(self, reset: np.ndarray) -> dict[str, Any]:
        """Infos batched as ``SyncVectorEnv`` batches them, ``_key`` masks included."""
        every = np.ones(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {
            "position": self.positions.copy(),
            "_position": every,
            "layout_id": self.layout_ids.copy(),
            "_layout_id": every.copy(),
        }
        if reset.any():
            infos["layout_index"] = np.where(reset, self.layout_indices, 0)
            infos["_layout_index"] = reset.copy()
        return infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """``rgb_array``: one frame per maze."""
        if self.render_mode != "rgb_array":
            return None
        return tuple(self._frames())

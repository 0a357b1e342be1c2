"""The rendered maze environment."""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from abco_envs.maze.layout import (
    DELTAS,
    OPEN_BITS,
    Action,
    generate_layout,
    layout_hash,
    validate_layout,
)
from abco_envs.maze.pool import LOOP_FRACTION, SPLITS, layout_pool
from abco_envs.maze.render import MazeRenderer

__all__ = ["MazeEnv", "state_observation_space", "state_features", "resolve_image_size"]

OBS_TYPES = ("image", "state")
LAYOUT_SOURCES = (*SPLITS, "procedural")


def resolve_image_size(image_size: int | tuple[int, int]) -> tuple[int, int]:
    """``64`` -> ``(64, 64)``; ``(h, w)`` stays as it is."""
    if isinstance(image_size, (int, np.integer)):
        return int(image_size), int(image_size)
    height, width = (int(v) for v in image_size)
    return height, width


def state_observation_space(n: int) -> spaces.Box:
    """Space of ``obs_type="state"``: one-hot row, one-hot col, then 4 open-side bits per cell."""
    return spaces.Box(0.0, 1.0, shape=(2 * n + 4 * n * n,), dtype=np.float32)


def state_features(cells: np.ndarray) -> np.ndarray:
    """The walls part of a state observation: per cell, 1.0 where open to N, S, E, W."""
    return ((cells[..., None] & OPEN_BITS) > 0).astype(np.float32).reshape(*cells.shape[:-2], -1)


def _check_options(n: int, obs_type: str, split: str) -> None:
    if obs_type not in OBS_TYPES:
        raise ValueError(f"unknown obs_type {obs_type!r}; expected one of {OBS_TYPES}")
    if split not in LAYOUT_SOURCES:
        raise ValueError(f"unknown split {split!r}; expected one of {LAYOUT_SOURCES}")
    if n < 2:
        raise ValueError(f"a maze needs at least 2x2 cells, got size={n}")


class MazeEnv(gym.Env[np.ndarray, np.int64]):
    """A 2D maze seen from above as an RGB image; walk from the top-left to the bottom-right.

    ## Description
    The maze of the ABCO paper (gym-maze), rebuilt headless and seedable. The agent (a blue
    dot) starts in cell ``(0, 0)``, marked blue, and must reach the goal cell ``(n-1, n-1)``,
    marked red. Layouts are spanning-tree mazes with about 20% of cells given one extra opening
    (so there are loops and often several shortest paths). By default each ``reset`` draws one
    of the 100 layouts of the canonical ``train`` split; ``split="test"`` uses the held-out
    ones and ``split="procedural"`` generates a fresh layout from the env's ``np_random``.

    ## Action Space
    ``Discrete(4)``: 0 = N (up), 1 = S (down), 2 = E (right), 3 = W (left), as
    :class:`~abco_envs.maze.layout.Action`. A move into a wall leaves the agent in place.

    ## Observation Space
    ``obs_type="image"`` (default): ``Box(0, 255, (H, W, 3), uint8)``, the rendered maze:
    white floor, black walls, blue start cell, red goal cell, blue agent dot. ``image_size``
    sets ``(H, W)`` (default 64; at least 2 pixels per cell). ``obs_type="state"``:
    ``Box(0, 1, (2n + 4n^2,), float32)``: one-hot agent row, one-hot agent column, then for each
    cell in row-major order 1.0 where it is open to N, S, E, W. Each observation is a new array.

    ## Rewards
    +1 on reaching the goal, otherwise ``-0.1 / (n * n)`` per step. An optimal episode of ``L``
    moves returns ``1 - (L - 1) * 0.1 / n**2``.

    ## Starting State
    The agent starts at ``(0, 0)``, or at ``options["start"]`` if given.

    ## Episode End
    Termination: the agent reaches the goal. Truncation: ``max_episode_steps`` (1000 by
    default, set through ``gym.make``) steps have passed.

    ## Reset Options
    ``layout``: an explicit ``(n, n)`` layout in gym-maze's encoding (validated);
    ``layout_index``: index into the env's split; ``start``: ``(row, col)`` start cell.

    ## Info
    ``position`` (int64 array ``[row, col]``), ``layout_id`` (structural hash) and, after reset,
    ``layout_index`` (-1 for an explicit or procedural layout).

    ## Registered Configurations
    ``AbcoMaze3x3-v0``, ``AbcoMaze5x5-v0``, ``AbcoMaze10x10-v0`` (``size`` 3, 5, 10).

    Example:
        >>> import gymnasium as gym
        >>> import abco_envs
        >>> env = gym.make("AbcoMaze5x5-v0")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, obs.dtype, info["position"].tolist()
        ((64, 64, 3), dtype('uint8'), [0, 0])
        >>> obs, reward, terminated, truncated, info = env.step(abco_envs.Action.S)
        >>> env.close()
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 8}

    def __init__(
        self,
        size: int = 5,
        render_mode: str | None = None,
        obs_type: str = "image",
        image_size: int | tuple[int, int] = 64,
        split: str = "train",
    ) -> None:
        _check_options(size, obs_type, split)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"unknown render_mode {render_mode!r}; expected one of"
                f" {self.metadata['render_modes']}"
            )
        self.size, self.obs_type, self.split = size, obs_type, split
        self.render_mode = render_mode
        self.image_size = resolve_image_size(image_size)
        self.renderer = MazeRenderer(size, *self.image_size)
        self.action_space = spaces.Discrete(4)
        if obs_type == "image":
            self.observation_space = spaces.Box(0, 255, (*self.image_size, 3), dtype=np.uint8)
        else:
            self.observation_space = state_observation_space(size)
        self._layouts = None if split == "procedural" else layout_pool(size).split(split)
        self._layout_ids = None if split == "procedural" else layout_pool(size).ids(split)
        self._goal = (size - 1, size - 1)
        self._step_penalty = -0.1 / (size * size)
        self._window: Any = None
        self._clock: Any = None
        self.cells: np.ndarray | None = None

    # -- episode ------------------------------------------------------------------------------

    def _choose_layout(self, options: dict[str, Any]) -> tuple[np.ndarray, int]:
        if options.get("layout") is not None:
            return validate_layout(options["layout"], self.size), -1
        if self._layouts is None:
            return generate_layout(self.size, self.np_random, LOOP_FRACTION), -1
        if options.get("layout_index") is not None:
            index = int(options["layout_index"])
            if not 0 <= index < len(self._layouts):
                raise IndexError(
                    f"layout_index {index} out of range for the {self.split!r} split"
                    f" of {len(self._layouts)} layouts"
                )
        else:
            index = int(self.np_random.integers(len(self._layouts)))
        return self._layouts[index], index

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``seed`` fixes the layout drawn and everything after it."""
        super().reset(seed=seed)
        options = options or {}
        cells, index = self._choose_layout(options)
        start = options.get("start")
        row, col = (0, 0) if start is None else (int(start[0]), int(start[1]))
        if not (0 <= row < self.size and 0 <= col < self.size):
            raise ValueError(f"start {start} is outside the {self.size}x{self.size} maze")
        self.cells = cells
        self.layout_index = index
        self.layout_id = (
            self._layout_ids[index] if index >= 0 and self._layout_ids else layout_hash(cells)
        )
        self._background = self.renderer.background(cells)
        self._walls = state_features(cells)
        self.row, self.col = row, col
        info = {"position": np.array([row, col]), "layout_id": self.layout_id,
                "layout_index": index}
        if self.render_mode == "human":
            self.render()
        return self._observe(), info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Move one cell N, S, E or W (or stay, against a wall)."""
        if self.cells is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = int(action)
        if not 0 <= a < 4:
            raise ValueError(f"invalid action {action!r}: expected 0 (N), 1 (S), 2 (E) or 3 (W)")
        if self.cells[self.row, self.col] & OPEN_BITS[a]:
            self.row += int(DELTAS[a, 0])
            self.col += int(DELTAS[a, 1])
        terminated = (self.row, self.col) == self._goal
        reward = 1.0 if terminated else self._step_penalty
        if self.render_mode == "human":
            self.render()
        info = {"position": np.array([self.row, self.col]), "layout_id": self.layout_id}
        return self._observe(), reward, terminated, False, info

    def _observe(self) -> np.ndarray:
        if self.obs_type == "image":
            return self.renderer.draw_agent(self._background.copy(), self.row, self.col)
        n = self.size
        obs = np.zeros(2 * n + 4 * n * n, dtype=np.float32)
        obs[self.row] = 1.0
        obs[n + self.col] = 1.0
        obs[2 * n :] = self._walls
        return obs

    # -- rendering ----------------------------------------------------------------------------

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the current frame; ``human``: draw it in a pygame window."""
        if self.cells is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        frame = self.renderer.draw_agent(self._background.copy(), self.row, self.col)
        if self.render_mode == "rgb_array":
            return frame
        if self.render_mode == "human":
            self._show(frame)
        return None

    def _show(self, frame: np.ndarray) -> None:
        import pygame  # only a person watching needs pygame

        scale = max(1, 448 // max(frame.shape[:2]))
        if self._window is None:
            pygame.display.init()  # the display alone: no audio device is needed
            pygame.display.set_caption(f"AbcoMaze{self.size}x{self.size}")
            self._window = pygame.display.set_mode(
                (frame.shape[1] * scale, frame.shape[0] * scale)
            )
            self._clock = pygame.time.Clock()
        surface = pygame.surfarray.make_surface(frame.swapaxes(0, 1))
        self._window.blit(pygame.transform.scale(surface, self._window.get_size()), (0, 0))
        pygame.event.pump()
        pygame.display.flip()
        self._clock.tick(self.metadata["render_fps"])

    def get_keys_to_action(self) -> dict[tuple[int, ...], int]:
        """Arrow keys for :func:`gymnasium.utils.play.play`."""
        import pygame

        return {
            (pygame.K_UP,): int(Action.N),
            (pygame.K_DOWN,): int(Action.S),
            (pygame.K_RIGHT,): int(Action.E),
            (pygame.K_LEFT,): int(Action.W),
        }

    def close(self) -> None:
        """Close the pygame window, if one was opened."""
        if self._window is not None:
            import pygame

            pygame.display.quit()
            self._window = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_window"] = state["_clock"] = None  # a window does not travel
        return state

"""The rendered maze environment."""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from abco_envs.maze.observation import (
    OBS_TYPES,
    image_observation_space,
    state_features,
    state_observation_space,
)
from abco_envs.maze.options import (
    LAYOUT_SOURCES,
    check_action,
    check_env_options,
    check_render_mode,
    check_reset_options,
    check_start,
    resolve_image_size,
)
from abco_envs.maze.render import MazeRenderer
from abco_envs.maze.reset import LayoutSource
from abco_envs.maze.rules import Action, MazeDynamics

# The helpers and constants below MazeEnv stay importable from here, where they used to live.
__all__ = ["MazeEnv", "maze_cells", "state_observation_space", "state_features",
           "resolve_image_size", "OBS_TYPES", "LAYOUT_SOURCES"]


class MazeEnv(gym.Env[np.ndarray, np.int64]):
    """A 2D maze seen from above as an RGB image; walk from the top-left to the bottom-right.

    ## Description
    The maze of the ABCO paper (gym-maze), rebuilt headless and seedable. The agent (a blue
    dot) starts in cell ``(0, 0)``, marked blue, and must reach the goal cell ``(n-1, n-1)``,
    marked red. Layouts are spanning-tree mazes with about 20% of cells given one extra opening
    (so there are loops and often several shortest paths). By default each ``reset`` draws one
    of the 100 layouts of the canonical ``train`` split; ``split="test"`` uses the held-out
    ones, ``split="procedural"`` the 10,000 layouts of the procedural split (those of the
    procedural datasets) and ``split="fresh"`` draws a fresh layout from the env's
    ``np_random``, one in no split and no dataset (see :mod:`abco_envs.maze.procedural`).

    ## Action Space
    ``Discrete(4)``: 0 = N (up), 1 = S (down), 2 = E (right), 3 = W (left), as
    :class:`~abco_envs.maze.rules.Action`. A move into a wall leaves the agent in place.
    Actions are Python or numpy integers; floats, strings, ``None`` and ``bool`` are refused
    with :class:`~abco_envs.errors.InvalidActionError`, as are integers outside ``0..3``.

    ## Observation Space
    ``obs_type="image"`` (default): ``Box(0, 255, (H, W, 3), uint8)``, the rendered maze:
    white floor, black walls, blue start cell, red goal cell, blue agent dot. ``image_size``
    sets ``(H, W)`` (default 64; at least 2 pixels per cell). ``obs_type="state"``:
    ``Box(0, 1, (2n + 4n^2,), float32)``: one-hot agent row, one-hot agent column, then for each
    cell in row-major order 1.0 where it is open to N, S, E, W. Each observation is a new array.

    ## Rewards
    +1 on reaching the goal, otherwise ``-0.1 / (n * n)`` per step. An optimal episode of ``L``
    moves returns ``1 - (L - 1) * 0.1 / n**2``. (All rules live in :mod:`abco_envs.maze.rules`.)

    ## Starting State
    The agent starts at ``(0, 0)``, or at ``options["start"]`` if given.

    ## Episode End
    Termination: the agent reaches the goal. Truncation: ``max_episode_steps`` (1000 by
    default, set through ``gym.make``) steps have passed.

    ## Reset Options
    ``layout``: an explicit ``(n, n)`` layout in gym-maze's encoding (validated);
    ``layout_index``: integer index into the env's split (not for ``split="fresh"``);
    ``start``: ``(row, col)`` start cell, integers, inside the maze and not the goal. Other
    keys, non-dict options and bad values raise :class:`~abco_envs.errors.InvalidOptionError`
    (:class:`~abco_envs.errors.OptionOutOfRangeError` for an index or cell out of range).

    ## Info
    ``position`` (int64 array ``[row, col]``), ``layout_id`` (structural hash) and, after reset,
    ``layout_index`` (-1 for an explicit or fresh layout).

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
        check_env_options(size, obs_type, split)
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.size, self.obs_type, self.split = int(size), obs_type, split
        self.render_mode = render_mode
        self.image_size = resolve_image_size(image_size, self.size)
        self.renderer = MazeRenderer(size, *self.image_size)
        self.action_space = spaces.Discrete(4)
        if obs_type == "image":
            self.observation_space = image_observation_space(*self.image_size)
        else:
            self.observation_space = state_observation_space(size)
        self._layouts = LayoutSource(size, split)
        self._dynamics = MazeDynamics(size)
        self._window: Any = None
        self._clock: Any = None
        self.cells: np.ndarray | None = None

    # -- episode ------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``seed`` fixes the layout drawn and everything after it."""
        super().reset(seed=seed)
        checked = check_reset_options(options)
        row, col = check_start(checked.get("start"), self.size)
        drawn = self._layouts.draw(
            self.np_random, checked.get("layout"), checked.get("layout_index")
        )
        self.cells, self.layout_index, self.layout_id = drawn.cells, drawn.index, drawn.layout_id
        # One maze's move table, as the batched kernel wants it: (1, n * n, 4).
        self._moves = drawn.moves[None]
        self._background = self.renderer.background(drawn.cells)
        # The state vector's walls part, behind zero one-hots: a step copies it and sets two.
        self._state_background = np.concatenate(
            [np.zeros(2 * self.size, dtype=np.float32), state_features(drawn.cells)]
        )
        self.row, self.col = row, col
        self._cell = row * self.size + col
        info = {"position": np.array([row, col]), "layout_id": self.layout_id,
                "layout_index": drawn.index}
        if self.render_mode == "human":
            self.render()
        return self._observe(), info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Move one cell N, S, E or W (or stay, against a wall)."""
        if self.cells is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_action(action)
        cell, reward, terminated = self._dynamics.step(self._moves, 0, self._cell, a)
        self._cell = int(cell)
        self.row, self.col = divmod(self._cell, self.size)
        if self.render_mode == "human":
            self.render()
        info = {"position": np.array([self.row, self.col]), "layout_id": self.layout_id}
        return self._observe(), float(reward), bool(terminated), False, info

    def _observe(self) -> np.ndarray:
        if self.obs_type == "image":
            return self.renderer.draw_agent(self._background.copy(), self.row, self.col)
        obs = self._state_background.copy()
        obs[self.row] = 1.0
        obs[self.size + self.col] = 1.0
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


def maze_cells(env: gym.Env[Any, Any]) -> np.ndarray:
    """The layout (cell bits) of the :class:`MazeEnv` under ``env``'s wrappers, drawn at its
    last reset.

    Raises:
        TypeError: ``env`` is not an abco maze.
        gymnasium.error.ResetNeeded: It was never reset.
    """
    maze = env.unwrapped
    if not isinstance(maze, MazeEnv):
        raise TypeError(f"{env} is not an abco maze")
    if maze.cells is None:
        raise gym.error.ResetNeeded("call reset() before asking for the maze's layout")
    return maze.cells

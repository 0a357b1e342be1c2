"""Maze layouts: the cell encoding, a seeded generator, validation and shortest paths.

A layout is an ``(n, n)`` integer array in gym-maze's encoding: each cell holds the bits of the
sides it is open to, ``N=1, E=2, S=4, W=8`` (named in :mod:`abco_envs.maze.rules`, with the
other rules). Cell ``(0, 0)`` is the top-left corner (the start) and ``(n - 1, n - 1)`` the
bottom-right one (the goal). Positions are ``(row, col)``.

Example:
    >>> import numpy as np
    >>> from abco_envs.maze.layout import generate_layout, count_passages, validate_layout
    >>> cells = generate_layout(5, np.random.default_rng(0), loop_fraction=0.0)
    >>> count_passages(cells)  # a perfect maze is a spanning tree: n*n - 1 passages
    24
    >>> validate_layout(cells).shape
    (5, 5)
"""

from __future__ import annotations

import hashlib
from collections import deque

import numpy as np

from abco_envs.errors import InvalidLayoutError
from abco_envs.maze.rules import (
    DELTAS,
    OPEN_BITS,
    OPEN_E,
    OPEN_N,
    OPEN_S,
    OPEN_W,
    START_POSITION,
    Action,
    goal_position,
)

__all__ = [
    "Action",
    "InvalidLayoutError",
    "DELTAS",
    "OPEN_BITS",
    "generate_layout",
    "validate_layout",
    "count_passages",
    "layout_hash",
    "distances_to",
    "shortest_path_length",
]


#: The action that undoes each action (N<->S, E<->W).
_OPPOSITE = np.array([Action.S, Action.N, Action.W, Action.E])


def _open(cells: np.ndarray, r: int, c: int, a: int) -> None:
    """Open the wall between cell (r, c) and its neighbour in direction ``a`` (both sides)."""
    dr, dc = DELTAS[a]
    cells[r, c] |= OPEN_BITS[a]
    cells[r + dr, c + dc] |= OPEN_BITS[_OPPOSITE[a]]


def generate_layout(
    n: int, rng: np.random.Generator, loop_fraction: float = 0.2
) -> np.ndarray:
    """Generate a maze: a recursive-backtracker spanning tree, then extra walls broken.

    The spanning tree has exactly ``n*n - 1`` passages (the DFS start cell is carved once,
    unlike the original gym-maze generator). Then ``round(loop_fraction * n * n)`` distinct
    cells each lose one more interior wall (chosen at random among their closed ones), which
    makes loops, as in the paper's sample mazes.

    Args:
        n: Cells per side (at least 2).
        rng: The generator every random choice is drawn from.
        loop_fraction: Share of cells that get one extra wall removed; 0 gives a perfect maze.

    Returns:
        A fresh ``(n, n)`` ``uint8`` array in gym-maze's encoding.
    """
    if n < 2:
        raise ValueError(f"a maze needs at least 2x2 cells, got n={n}")
    if not 0.0 <= loop_fraction <= 1.0:
        raise ValueError(f"loop_fraction must be in [0, 1], got {loop_fraction}")
    cells = np.zeros((n, n), dtype=np.uint8)
    visited = np.zeros((n, n), dtype=bool)
    start = (int(rng.integers(n)), int(rng.integers(n)))
    visited[start] = True
    stack = [start]
    while stack:
        r, c = stack[-1]
        options = [
            a
            for a in range(4)
            if 0 <= r + DELTAS[a][0] < n
            and 0 <= c + DELTAS[a][1] < n
            and not visited[r + DELTAS[a][0], c + DELTAS[a][1]]
        ]
        if not options:
            stack.pop()
            continue
        a = options[int(rng.integers(len(options)))]
        _open(cells, r, c, a)
        nxt = (r + int(DELTAS[a][0]), c + int(DELTAS[a][1]))
        visited[nxt] = True
        stack.append(nxt)

    n_loops = int(round(loop_fraction * n * n))
    for flat in rng.choice(n * n, size=n_loops, replace=False):
        r, c = divmod(int(flat), n)
        closed = [
            a
            for a in range(4)
            if 0 <= r + DELTAS[a][0] < n
            and 0 <= c + DELTAS[a][1] < n
            and not cells[r, c] & OPEN_BITS[a]
        ]
        if closed:
            _open(cells, r, c, closed[int(rng.integers(len(closed)))])
    return cells


def validate_layout(cells: object, n: int | None = None) -> np.ndarray:
    """Check a layout and return it as a fresh ``uint8`` array.

    Args:
        cells: Anything ``np.asarray`` turns into an ``(n, n)`` integer array.
        n: The expected size, if the caller has one.

    Raises:
        InvalidLayoutError: Wrong shape or dtype, values outside 0..15, an opening through the
            outer border, a side open from one cell but not from its neighbour, or cells that
            cannot be reached from the start.
    """
    arr = np.asarray(cells)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] < 2:
        raise InvalidLayoutError(f"a layout must be a square (n, n) array, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise InvalidLayoutError(f"expected a {n}x{n} layout, got {arr.shape[0]}x{arr.shape[1]}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise InvalidLayoutError(f"layout cells must be integers, got dtype {arr.dtype}")
    if arr.min() < 0 or arr.max() > 15:
        raise InvalidLayoutError("layout cells must be in 0..15 (bits N=1, E=2, S=4, W=8)")
    out = arr.astype(np.uint8)
    size = out.shape[0]
    for name, bit, edge in (("N", OPEN_N, out[0]), ("S", OPEN_S, out[-1]),
                            ("W", OPEN_W, out[:, 0]), ("E", OPEN_E, out[:, -1])):
        if np.any(edge & bit):
            raise InvalidLayoutError(f"a border cell is open to the outside on side {name}")
    east = (out[:, :-1] & OPEN_E) > 0
    west = (out[:, 1:] & OPEN_W) > 0
    if np.any(east != west):
        r, c = np.argwhere(east != west)[0]
        raise InvalidLayoutError(
            f"inconsistent wall between cells ({r}, {c}) and ({r}, {c + 1}): E and W bits differ"
        )
    south = (out[:-1, :] & OPEN_S) > 0
    north = (out[1:, :] & OPEN_N) > 0
    if np.any(south != north):
        r, c = np.argwhere(south != north)[0]
        raise InvalidLayoutError(
            f"inconsistent wall between cells ({r}, {c}) and ({r + 1}, {c}): S and N bits differ"
        )
    dist = distances_to(out, START_POSITION)
    if np.any(dist < 0):
        r, c = np.argwhere(dist < 0)[0]
        raise InvalidLayoutError(
            f"disconnected layout: cell ({r}, {c}) cannot be reached from the start (0, 0)"
            f" ({int(np.sum(dist < 0))} of {size * size} cells unreachable)"
        )
    return out


def count_passages(cells: np.ndarray) -> int:
    """Number of open walls between neighbouring cells (each counted once)."""
    return int(np.count_nonzero(cells & OPEN_E) + np.count_nonzero(cells & OPEN_S))


def layout_hash(cells: np.ndarray) -> str:
    """Structural id of a layout: the same walls give the same id, whatever the seed."""
    arr = np.ascontiguousarray(cells, dtype=np.uint8)
    digest = hashlib.sha256(arr.tobytes()).hexdigest()[:12]
    return f"{arr.shape[0]}x{arr.shape[1]}-{digest}"


def distances_to(cells: np.ndarray, target: tuple[int, int]) -> np.ndarray:
    """Breadth-first search: moves needed from every cell to ``target`` (-1 if unreachable)."""
    n = cells.shape[0]
    dist = np.full(cells.shape, -1, dtype=np.int64)
    dist[target] = 0
    queue = deque([target])
    while queue:
        r, c = queue.popleft()
        for a in range(4):
            if cells[r, c] & OPEN_BITS[a]:
                nr, nc = r + int(DELTAS[a][0]), c + int(DELTAS[a][1])
                if 0 <= nr < n and 0 <= nc < n and dist[nr, nc] < 0:
                    dist[nr, nc] = dist[r, c] + 1
                    queue.append((nr, nc))
    return dist


def shortest_path_length(cells: np.ndarray) -> int:
    """Moves on a shortest path from the start (0, 0) to the goal (n-1, n-1)."""
    return int(distances_to(cells, goal_position(cells.shape[0]))[START_POSITION])

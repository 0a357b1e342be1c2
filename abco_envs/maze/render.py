"""Headless numpy rendering of mazes: a background per layout, then the agent's dot.

Drawing is split so stepping stays cheap: the walls, start and goal of a layout are drawn once
into a background image; each frame is that background plus the agent's dot, whose pixels are
precomputed per cell as flat indices. No display and no pygame are involved.
"""

from __future__ import annotations

import numpy as np

from abco_envs.maze.rules import OPEN_E, OPEN_N, OPEN_S, OPEN_W, START_POSITION, goal_position

__all__ = ["MazeRenderer", "cell_edges", "FLOOR", "WALL", "START", "GOAL", "AGENT", "PATH"]

FLOOR = np.array([255, 255, 255], dtype=np.uint8)
WALL = np.array([0, 0, 0], dtype=np.uint8)
START = np.array([110, 150, 255], dtype=np.uint8)  # blue start cell, lighter than the agent
GOAL = np.array([230, 30, 30], dtype=np.uint8)
AGENT = np.array([0, 0, 200], dtype=np.uint8)
PATH = np.array([255, 160, 0], dtype=np.uint8)  # orange: visible on white, blue and red


def cell_edges(n: int, size: int) -> np.ndarray:
    """``(n + 1,)`` pixel borders of ``n`` cells across ``size`` pixels: ``round(k * size / n)``.

    Example:
        >>> cell_edges(10, 64).tolist()
        [0, 6, 13, 19, 26, 32, 38, 45, 51, 58, 64]
    """
    return np.round(np.linspace(0, size, n + 1)).astype(int)


class MazeRenderer:
    """Renders ``n`` x ``n`` layouts into ``(height, width, 3)`` uint8 images.

    Cell borders fall on ``round(k * height / n)`` so any image size works, down to a few
    pixels per cell; walls are at least one pixel thick.

    Args:
        n: Cells per side.
        height: Image height in pixels.
        width: Image width in pixels.
    """

    def __init__(self, n: int, height: int, width: int) -> None:
        if height < 2 * n or width < 2 * n:
            raise ValueError(
                f"image {height}x{width} is too small for a {n}x{n} maze:"
                f" at least 2 pixels per cell are needed ({2 * n}x{2 * n})"
            )
        self.n, self.height, self.width = n, height, width
        self.rows, self.cols = cell_edges(n, height), cell_edges(n, width)
        cell = min(height, width) / n
        self.wall = max(1, int(round(cell / 12)))
        self.dot_pixels = self._dot_pixels(cell)
        #: Byte offsets of each cell's dot in a C-contiguous frame, and the bytes to write
        #: there: one flat fancy-index assignment draws the agent (a few times faster than
        #: assigning a colour to pixel rows).
        self.dot_bytes = (self.dot_pixels[:, :, None] * 3 + np.arange(3)).reshape(n * n, -1)
        self.dot_colour = np.tile(AGENT, self.dot_pixels.shape[1])

    def _dot_pixels(self, cell: float) -> np.ndarray:
        """Flat pixel indices of the agent's dot in every cell, padded to one length."""
        radius = max(0.5, 0.3 * cell)
        per_cell = []
        for r in range(self.n):
            for c in range(self.n):
                cy = (self.rows[r] + self.rows[r + 1] - 1) / 2
                cx = (self.cols[c] + self.cols[c + 1] - 1) / 2
                ys, xs = np.mgrid[self.rows[r] : self.rows[r + 1], self.cols[c] : self.cols[c + 1]]
                dist2 = (ys - cy) ** 2 + (xs - cx) ** 2
                inside = dist2 <= radius**2
                if not inside.any():  # tiny cells: at least the centre pixel(s)
                    inside = dist2 == dist2.min()
                per_cell.append((ys[inside] * self.width + xs[inside]).ravel())
        longest = max(len(p) for p in per_cell)
        # Pad by repeating a pixel: writing it twice is harmless and keeps one array.
        return np.stack([np.pad(p, (0, longest - len(p)), mode="edge") for p in per_cell])

    def background(self, cells: np.ndarray) -> np.ndarray:
        """The layout without the agent: floor, walls, start (blue) and goal (red) cells."""
        n, t = self.n, self.wall
        img = np.empty((self.height, self.width, 3), dtype=np.uint8)
        img[:] = FLOOR
        rows, cols = self.rows, self.cols
        for (r, c), colour in ((START_POSITION, START), (goal_position(n), GOAL)):
            img[rows[r] : rows[r + 1], cols[c] : cols[c + 1]] = colour
        lo, hi = t // 2, t - t // 2
        for r in range(n):
            for c in range(n):
                y0, y1, x0, x1 = rows[r], rows[r + 1], cols[c], cols[c + 1]
                # Each wall is drawn by the cell on its north or west side (borders included),
                # stretched by half a wall at both ends so corners close.
                if not cells[r, c] & OPEN_N:
                    img[max(0, y0 - lo) : y0 + hi, max(0, x0 - lo) : x1 + hi] = WALL
                if not cells[r, c] & OPEN_W:
                    img[max(0, y0 - lo) : y1 + hi, max(0, x0 - lo) : x0 + hi] = WALL
                if r == n - 1 and not cells[r, c] & OPEN_S:
                    img[y1 - t : y1, max(0, x0 - lo) : x1] = WALL
                if c == n - 1 and not cells[r, c] & OPEN_E:
                    img[max(0, y0 - lo) : y1, x1 - t : x1] = WALL
        return img

    def draw_agent(self, img: np.ndarray, row: int, col: int) -> np.ndarray:
        """Draw the agent's dot into ``img`` (in place) and return it."""
        if img.flags.c_contiguous:
            img.reshape(-1)[self.dot_bytes[row * self.n + col]] = self.dot_colour
        else:  # reshape(-1) would copy: write through a pixel view instead
            img[np.unravel_index(self.dot_pixels[row * self.n + col], img.shape[:2])] = AGENT
        return img

    def frame(self, cells: np.ndarray, row: int, col: int) -> np.ndarray:
        """A fresh image of ``cells`` with the agent at ``(row, col)``."""
        return self.draw_agent(self.background(cells), row, col)

    def cell_centre(self, row: int, col: int) -> tuple[float, float]:
        """Pixel coordinates (y, x) of the centre of cell ``(row, col)``."""
        return (
            (self.rows[row] + self.rows[row + 1] - 1) / 2,
            (self.cols[col] + self.cols[col + 1] - 1) / 2,
        )

    def draw_path(
        self, img: np.ndarray, positions: np.ndarray, colour: np.ndarray = PATH
    ) -> np.ndarray:
        """Draw the line through the centres of ``positions`` ((T, 2) cells) into ``img``."""
        width = max(1, self.wall)
        for (r0, c0), (r1, c1) in zip(positions[:-1], positions[1:]):
            (y0, x0), (y1, x1) = self.cell_centre(r0, c0), self.cell_centre(r1, c1)
            steps = int(max(abs(y1 - y0), abs(x1 - x0))) + 1
            for t in np.linspace(0.0, 1.0, steps):
                y, x = int(round(y0 + t * (y1 - y0))), int(round(x0 + t * (x1 - x0)))
                img[max(0, y - width // 2) : y + width - width // 2,
                    max(0, x - width // 2) : x + width - width // 2] = colour
        return img

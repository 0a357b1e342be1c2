"""The maze networks for unseen layouts: :class:`CellNet` (``--arch cellnet``) and, with its
value-iteration planner (:class:`ValuePlanner`), ``cellplan``, the ``general`` preset's.

Both read a rendered maze cell by cell and tie no weight to a position, so the same weights
run on any layout and any maze size.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from abco_envs.maze.render import cell_edges
from abco_envs.maze.rules import DELTAS
from abco_train.networks.layers import SelfAttention2d, image_input

#: The floor of the planner's action values before the log (a walled-off move).
LOG_FLOOR = 1e-6

__all__ = ["cell_centres", "CellAverage", "CellReadout", "ValuePlanner", "CellNet", "PlannedHead",
           "CELLNET_IDM_ITERATIONS", "LOG_FLOOR"]  # fmt: skip


def cell_centres(grid: int, height: int, width: int) -> torch.Tensor:
    """``(1, grid, grid, 2)`` centres of a maze's cells as ``grid_sample`` coordinates.

    Cell borders fall where the renderer draws them (``round(k * height / grid)``,
    :class:`abco_envs.maze.render.MazeRenderer`); ``x`` and ``y`` are in ``[-1, 1]`` over the
    image's extent (``align_corners=False``), so they address any feature map that covers
    the whole image.
    """
    rows, cols = cell_edges(grid, height), cell_edges(grid, width)
    y = (rows[:-1] + rows[1:]) / height - 1.0  # the middle of each band of rows, normalised
    x = (cols[:-1] + cols[1:]) / width - 1.0
    yy, xx = np.meshgrid(y, x, indexing="ij")
    return torch.as_tensor(np.stack([xx, yy], axis=-1)[None], dtype=torch.float32)


class CellAverage(nn.Module):
    """The mean (``total``: the sum) of a ``(B, C, H, W)`` map over each cell of an
    ``n x n`` maze: ``(B, C, n, n)``.

    Cell borders fall where the renderer draws them (:func:`abco_envs.maze.render.cell_edges`),
    so every cell takes exactly its own pixels: ILPO's ``cells`` target, how much each cell
    changed. (:func:`cell_centres` reads a feature map at each cell's centre instead: the cell
    networks' convolutions have already spread a cell's content there.)
    """

    rows: torch.Tensor  # the buffers, typed (register_buffer sets them)
    cols: torch.Tensor

    def __init__(self, grid: int, height: int, width: int, total: bool = False) -> None:
        super().__init__()
        self.grid = int(grid)
        self.register_buffer("rows", self._means(grid, height, total), persistent=False)
        self.register_buffer("cols", self._means(grid, width, total), persistent=False)

    @staticmethod
    def _means(grid: int, size: int, total: bool) -> torch.Tensor:
        """``(grid, size)``: row ``i`` averages (``total``: sums) the pixels of band ``i``."""
        edges = cell_edges(grid, size)
        m = np.zeros((grid, size), dtype=np.float32)
        for i in range(grid):
            m[i, edges[i] : edges[i + 1]] = 1.0 if total else 1.0 / (edges[i + 1] - edges[i])
        return torch.from_numpy(m)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.rows @ x @ self.cols.T


class CellReadout(nn.Module):
    """Global read-out of a cell feature map: attention pooling and max pooling.

    A 1x1 projection of the input cell features ``x`` (where the agent's dot is, once
    learned) gives one logit per cell; the softmax over cells weights the reasoned features
    ``h``: ``sum_i softmax(w . x_i) h_i``, concatenated with ``max_i h_i``. Both are sums or
    maxima over cells, so the output does not depend on where a pattern lies, only on the
    features: permuting the cells of ``x`` and ``h`` alike leaves it unchanged.
    """

    def __init__(self, in_channels: int, channels: int) -> None:
        super().__init__()
        self.where = nn.Conv2d(in_channels, 1, 1)
        self.out_features = 2 * channels

    def weights(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, n*n)`` softmax weights over the cells of ``x`` (the agent's cell, once learned)."""
        return torch.softmax(self.where(x).flatten(1), dim=1)

    @staticmethod
    def at(maps: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        """``(B, C)``: the ``(B, C, n, n)`` maps averaged with ``weights``."""
        return torch.bmm(maps.flatten(2), weights.unsqueeze(-1)).squeeze(-1)

    def forward(self, x: torch.Tensor, h: torch.Tensor,
                weights: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
        """``(B, 2C)`` features of ``h`` ``(B, C, n, n)`` read where ``x`` points
        (``weights``: :meth:`weights` of ``x``, when the caller has them already)."""
        weights = self.weights(x) if weights is None else weights
        return torch.cat([self.at(h, weights), h.flatten(2).amax(dim=2)], dim=1)


class ValuePlanner(nn.Module):
    """Value iteration over the cell grid (Tamar et al.'s value iteration networks, on cells).

    From the cell features ``x`` two 1x1 projections give, per cell, how much it is the goal
    (``r``, a sigmoid) and, per action, how open its side is (``g_a``, a sigmoid: 0 where a
    wall stops the move). Then ``steps`` rounds of

        ``V <- max(r, max_a gamma * g_a * V(neighbour_a))``,   ``V_0 = r``,

    where the neighbour of a cell in action ``a``'s direction comes from
    :data:`abco_envs.maze.rules.DELTAS` (zero outside the maze). With exact ``r`` and ``g``,
    ``V = gamma ** d`` for a cell ``d`` moves from the goal once ``steps >= d``, and
    ``Q_a = gamma * g_a * V(neighbour_a)`` is largest for the moves of a shortest path. The
    output is ``log Q`` (floored at :data:`LOG_FLOOR`), whose differences are path lengths
    (``log gamma`` per move) whatever the distance to the goal. Every round is a few
    element-wise operations on ``(B, 4, n, n)``, so ``n * n`` rounds (any path) cost little
    beside the convolutions.

    Args:
        channels: Channels of the cell features.
        grid: Cells per side (``steps`` defaults to ``grid * grid``).
        gamma: Discount per move.
        steps: Rounds of value iteration.
    """

    def __init__(self, channels: int, grid: int, gamma: float = 0.9,
                 steps: int | None = None) -> None:  # fmt: skip
        super().__init__()
        self.goal = nn.Conv2d(channels, 1, 1)
        self.open = nn.Conv2d(channels, len(DELTAS), 1)
        self.gamma = float(gamma)
        self.steps = int(grid) ** 2 if steps is None else int(steps)

    @staticmethod
    def neighbours(v: torch.Tensor) -> torch.Tensor:
        """``(B, 4, n, n)``: for each action, the value of the cell it moves to (0 off the
        maze) of the ``(B, 1, n, n)`` values ``v``."""
        n = v.shape[-1]
        padded = F.pad(v, (1, 1, 1, 1))
        return torch.cat([padded[:, :, 1 + dr:1 + dr + n, 1 + dc:1 + dc + n]
                          for dr, dc in DELTAS.tolist()], dim=1)  # fmt: skip

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 4, n, n)`` log action values of the ``(B, C, n, n)`` cell features."""
        return self.iterate(torch.sigmoid(self.goal(x)), self.gamma * torch.sigmoid(self.open(x)))

    def iterate(self, r: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """``(B, 4, n, n)`` log action values of goal maps ``r`` ``(B, 1, n, n)`` and
        discounted openness ``g`` ``(B, 4, n, n)`` (``gamma * g_a``)."""
        v = r
        for _ in range(self.steps):
            v = torch.maximum(r, (g * self.neighbours(v)).amax(dim=1, keepdim=True))
        return torch.log((g * self.neighbours(v)).clamp_min(LOG_FLOOR))


class CellNet(nn.Module):
    """A maze network that reasons over the whole maze, cell by cell, with no weight tied to a
    position (``cellnet``; with ``plan``, ``cellplan``, the ``general`` preset's policy).

    1. A convolutional stem over the frame, ``conv 4x4/4 (C/2) -> conv 3x3 (C) -> conv 3x3
       (C)`` (receptive field 20 pixels: a 5x5 cell is 12.8 pixels wide on 64x64 frames), read
       at each maze cell's centre (bilinear ``grid_sample``): an ``(n, n)`` grid of cell
       features, each seeing its cell's walls, colour and dot.
    2. SAGAN self-attention over the ``n * n`` cells (as the paper places it after the second
       stage).
    3. ``iterations`` steps of one weight-shared residual block over the cell grid, each step
       re-reading the cell features (``h <- h + conv(lrelu(conv([h, x])))``, two 3x3
       convolutions: information moves up to two cells a step), so shortest-path-like
       reasoning can travel from the goal to the agent; the default, ``2 * n`` steps, covers
       paths of ``4n`` cells (the longest distance to the goal in 1,000 procedural layouts:
       18 cells on 5x5, 44 on 10x10; 99% of them within 16 and 33).
    4. Self-attention again, then :class:`CellReadout` (attention pooling at the agent, max
       pooling), ``2C`` features: no flattened, position-tied layer.
    5. With ``plan`` (``cellplan``), a :class:`ValuePlanner` over the cell features, read at
       the agent with the read-out's weights: 4 more features, the log action values, which
       :class:`PlannedHead` adds to its logits.

    The parameters do not depend on the maze size: the same weights run on any ``n``.

    Args:
        image_shape: ``(H, W, C)`` of the frames (or of frame + difference channels).
        grid: Cells per side of the maze.
        attention: Include the two self-attention modules.
        channels: ``C``.
        iterations: Recurrent steps (default ``2 * grid``).
        plan: Add the value-iteration planner's 4 features (last).
    """

    centres: torch.Tensor  # the buffer, typed (register_buffer sets it)

    def __init__(self, image_shape: tuple[int, int, int], grid: int, attention: bool = True,
                 channels: int = 32, iterations: int | None = None,
                 plan: bool = False) -> None:  # fmt: skip
        super().__init__()
        h, w, c = image_shape
        self.grid = int(grid)
        self.iterations = 2 * self.grid if iterations is None else int(iterations)
        half = channels // 2
        self.stem = nn.Sequential(
            nn.Conv2d(c, half, 4, stride=4), nn.LeakyReLU(),
            nn.Conv2d(half, channels, 3, padding=1), nn.LeakyReLU(),
            nn.Conv2d(channels, channels, 3, padding=1), nn.LeakyReLU(),
        )  # fmt: skip
        self.register_buffer("centres", cell_centres(self.grid, h, w), persistent=False)
        self.attend_in = SelfAttention2d(channels) if attention else nn.Identity()
        self.step1 = nn.Conv2d(2 * channels, channels, 3, padding=1)
        self.step2 = nn.Conv2d(channels, channels, 3, padding=1)
        self.attend_out = SelfAttention2d(channels) if attention else nn.Identity()
        self.readout = CellReadout(channels, channels)
        self.planner = ValuePlanner(channels, self.grid) if plan else None
        self.out_features = self.readout.out_features + (len(DELTAS) if plan else 0)

    def cells(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C, n, n)`` cell features of ``(B, H, W, C)`` images."""
        features = self.stem(image_input(x))
        grid = self.centres.expand(features.shape[0], -1, -1, -1)
        return F.grid_sample(features, grid, mode="bilinear", align_corners=False)

    def reason(self, x: torch.Tensor) -> torch.Tensor:
        """The recurrent steps over the cell grid, from ``h = x``.

        ``step1`` reads ``[h, x]``; a convolution is linear in its input channels, so it is
        computed as its ``h`` half plus its ``x`` half, and the ``x`` half (with the bias),
        the same at every step, once: the same function with fewer operations than
        concatenating ``[h, x]`` at each step (the sums are ordered differently, so the
        results agree to rounding, not to the bit).
        """
        c = x.shape[1]
        weight = self.step1.weight
        fixed = F.conv2d(x, weight[:, c:], self.step1.bias, padding=1)
        h = x
        for _ in range(self.iterations):
            h = h + self.step2(F.leaky_relu(F.conv2d(h, weight[:, :c], None, padding=1) + fixed))
        return h

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Pooled features of a batch of ``(H, W, C)`` images."""
        cells = self.attend_in(self.cells(x))
        weights = self.readout.weights(cells)  # where the agent is: read once, used twice
        features = self.readout(cells, self.attend_out(self.reason(cells)), weights)
        if self.planner is None:
            return features
        return torch.cat([features, self.readout.at(self.planner(cells), weights)], dim=1)


class PlannedHead(nn.Module):
    """The action layer of a ``cellplan`` policy: ``mlp`` (the cell networks' ``FC 128 ->
    actions``) over all features, plus ``scale * log Q_a`` of the planner's last ``n_actions``
    features (``scale`` learned, starting at ``1 / -log gamma``, the planner's ``gamma``: one
    logit per move of path length)."""

    def __init__(self, mlp: nn.Module, n_actions: int, gamma: float) -> None:
        super().__init__()
        self.n_actions = n_actions
        self.mlp = mlp
        self.scale = nn.Parameter(torch.tensor(-1.0 / float(np.log(gamma))))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Action logits."""
        return self.mlp(features) + self.scale * features[:, -self.n_actions:]



#: Recurrent steps of the ``cellnet`` IDM (the policy's: ``2 * n``).
CELLNET_IDM_ITERATIONS = 2

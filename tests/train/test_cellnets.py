"""The maze networks for unseen layouts (:mod:`abco_train.networks.cells`): the value-iteration
planner of ``cellplan`` and what both cell networks promise (no weight tied to a position)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces

from abco_envs.maze.layout import distances_to, generate_layout
from abco_envs.maze.rules import DELTAS, OPEN_BITS, goal_position
from abco_train.config.run import CELL_ARCHS, ConfigError, RunConfig
from abco_train.methods.registry import resolve_config
from abco_train.networks.builders import build_networks
from abco_train.networks.cells import LOG_FLOOR, PlannedHead, ValuePlanner

FRAMES = spaces.Box(0, 255, (64, 64, 3), np.uint8)


def _exact_inputs(cells: np.ndarray, gamma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The planner's goal map and discounted openness of a layout, as a perfect stem gives."""
    n = cells.shape[0]
    r = torch.zeros(1, 1, n, n)
    r[0, 0, goal_position(n)[0], goal_position(n)[1]] = 1.0
    opened = np.stack([(cells & bit) > 0 for bit in OPEN_BITS])  # (4, n, n)
    return r, gamma * torch.as_tensor(opened[None], dtype=torch.float32)


@pytest.mark.parametrize(("n", "seed"), [(5, 0), (5, 1), (10, 0), (10, 7)])
def test_exact_planner_follows_shortest_paths(n: int, seed: int) -> None:
    """With a perfect goal map and walls, the best moves are the shortest path's, and
    ``exp(max log Q) = gamma ** distance`` from every cell (the loops included)."""
    cells = generate_layout(n, np.random.default_rng(seed))
    dist = distances_to(cells, goal_position(n))
    planner = ValuePlanner(channels=1, grid=n)
    log_q = planner.iterate(*_exact_inputs(cells, planner.gamma))[0].numpy()
    for row in range(n):
        for col in range(n):
            if (row, col) == goal_position(n):
                continue
            best = log_q[:, row, col].max()
            assert np.exp(best) == pytest.approx(planner.gamma ** dist[row, col], rel=1e-4)
            for a in np.flatnonzero(log_q[:, row, col] >= best - 1e-5):
                dr, dc = DELTAS[a]
                assert cells[row, col] & OPEN_BITS[a], "a best move runs into a wall"
                assert dist[row + dr, col + dc] == dist[row, col] - 1


def test_planner_floors_walled_moves() -> None:
    cells = generate_layout(5, np.random.default_rng(3))
    planner = ValuePlanner(channels=1, grid=5)
    log_q = planner.iterate(*_exact_inputs(cells, planner.gamma))[0]
    walled = torch.as_tensor(np.stack([(cells & bit) == 0 for bit in OPEN_BITS]))
    assert log_q[walled].numpy() == pytest.approx(np.log(LOG_FLOOR))


def test_too_few_steps_leave_far_cells_unvalued() -> None:
    """The rounds bound the path length the planner sees (why the default is ``n * n``)."""
    cells = generate_layout(5, np.random.default_rng(0))
    dist = distances_to(cells, goal_position(5))
    planner = ValuePlanner(channels=1, grid=5, steps=2)
    best = planner.iterate(*_exact_inputs(cells, planner.gamma))[0].amax(dim=0).numpy()
    assert best[dist > 3] == pytest.approx(np.log(LOG_FLOOR))
    assert np.all(best[(dist >= 1) & (dist <= 3)] > np.log(LOG_FLOOR))


def test_planned_head_adds_scaled_log_values() -> None:
    head = PlannedHead(torch.nn.Linear(6, 4), 4, gamma=0.9)
    assert head.scale.item() == pytest.approx(1 / -np.log(0.9))
    features = torch.randn(2, 6)
    expected = head.mlp(features) + head.scale * features[:, -4:]
    torch.testing.assert_close(head(features), expected)


@pytest.mark.parametrize("arch", CELL_ARCHS)
@pytest.mark.parametrize("grid", [5, 10])
def test_cell_networks_run_on_both_tasks(arch: str, grid: int) -> None:
    policy, idm = build_networks(FRAMES, 4, arch, True, "difference", grid=grid)
    obs = torch.randint(0, 256, (3, 64, 64, 3), dtype=torch.uint8)
    assert policy(obs).shape == (3, 4) and idm(obs, obs).shape == (3, 4)
    assert policy.encoder.iterations == 2 * grid and idm.encoder.iterations == 2
    planned = arch == "cellplan"
    # 2C pooled features (and the planner's 4), whatever the grid: no position-tied layer
    assert policy.encoder.out_features == 64 + (4 if planned else 0)
    assert isinstance(policy.head, PlannedHead) is planned
    assert (policy.encoder.planner is not None) is planned
    assert idm.encoder.planner is None  # the IDM's move is local: it plans nothing
    if planned:
        assert policy.encoder.planner.steps == grid * grid
    with pytest.raises(ValueError, match="needs the maze's grid size"):
        build_networks(FRAMES, 4, arch, True, "difference")


@pytest.mark.parametrize("arch", CELL_ARCHS)
def test_cell_weights_do_not_depend_on_the_maze_size(arch: str) -> None:
    """No weight is tied to a position: a 5x5 network's weights run a 10x10 maze as they are."""
    small, _ = build_networks(FRAMES, 4, arch, True, "difference", grid=5)
    large, _ = build_networks(FRAMES, 4, arch, True, "difference", grid=10)
    shapes = {k: v.shape for k, v in small.state_dict().items()}
    assert shapes == {k: v.shape for k, v in large.state_dict().items()}
    large.load_state_dict(small.state_dict())
    env = gym.make("AbcoMaze10x10-v0")
    obs, _ = env.reset(seed=0)
    assert large(torch.from_numpy(obs[None])).shape == (1, 4)


@pytest.mark.parametrize("arch", CELL_ARCHS)
def test_cell_networks_refuse_frame_pairs(arch: str) -> None:
    with pytest.raises(ConfigError, match=f"--arch {arch} reads a transition as one frame"):
        resolve_config(RunConfig(env="AbcoMaze5x5-v0", arch=arch,
                                 method_options={"idm_input": "pair"}))

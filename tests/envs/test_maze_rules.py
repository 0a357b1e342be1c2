"""The maze's rules module: the step kernel against the rules read directly, and the layering."""

import ast
import pathlib
import re

import numpy as np
import pytest

import abco_envs
from abco_envs import MAZE_SIZES
from abco_envs.maze.layout import shortest_path_length
from abco_envs.maze.pool import layout_pool
from abco_envs.maze.rules import (
    DELTAS,
    GOAL_REWARD,
    MAX_EPISODE_STEPS,
    OPEN_BITS,
    OPEN_E,
    OPEN_N,
    OPEN_S,
    OPEN_W,
    Action,
    MazeDynamics,
    episode_return,
    goal_position,
    move_table,
    optimal_return,
    step_penalty,
)

PACKAGE = pathlib.Path(abco_envs.__file__).parent


def test_bits_and_moves_are_gym_mazes():
    assert (OPEN_N, OPEN_E, OPEN_S, OPEN_W) == (1, 2, 4, 8)
    assert OPEN_BITS[[Action.N, Action.S, Action.E, Action.W]].tolist() == [1, 4, 2, 8]
    assert DELTAS[[Action.N, Action.S, Action.E, Action.W]].tolist() == [
        [-1, 0], [1, 0], [0, 1], [0, -1]]
    assert MAX_EPISODE_STEPS == 1000 and GOAL_REWARD == 1.0
    assert step_penalty(5) == -0.1 / 25


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_move_table_follows_the_open_bits(n):
    cells = layout_pool(n).train[:10]
    table = move_table(cells)
    assert table.shape == (10, n * n, 4)
    for k in range(len(cells)):
        for r in range(n):
            for c in range(n):
                for a in Action:
                    moved = cells[k, r, c] & OPEN_BITS[a]
                    dr, dc = DELTAS[a] if moved else (0, 0)
                    assert table[k, r * n + c, a] == (r + dr) * n + (c + dc)


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_one_maze_step_equals_the_batched_step(n):
    dynamics = MazeDynamics(n)
    moves = move_table(layout_pool(n).train)
    rng = np.random.default_rng(n)
    maze = rng.integers(len(moves), size=500)
    cell = rng.integers(n * n, size=500)
    action = rng.integers(4, size=500)
    batched = dynamics.step(moves, maze, cell, action)
    for i in range(500):
        one = dynamics.step(moves, int(maze[i]), int(cell[i]), int(action[i]))
        assert [x[i] for x in batched] == list(one)
    goal = goal_position(n)
    arrived = batched[0] == goal[0] * n + goal[1]
    assert np.array_equal(batched[2], arrived)
    assert np.array_equal(batched[1], np.where(arrived, GOAL_REWARD, step_penalty(n)))


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_returns_are_the_sums_of_step_rewards(n):
    for steps in (1, 2, 17, MAX_EPISODE_STEPS):
        rewards = [step_penalty(n)] * (steps - 1)
        assert episode_return(n, steps, True) == pytest.approx(sum(rewards) + GOAL_REWARD)
        assert episode_return(n, steps, False) == pytest.approx(step_penalty(n) * steps)
    lengths = np.array([shortest_path_length(c) for c in layout_pool(n).train])
    assert np.allclose(optimal_return(n, lengths), episode_return(n, lengths, True))


def _modules():
    return sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_name_is_imported_across_modules(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("abco"):
            private = [a.name for a in node.names if a.name.startswith("_")]
            assert not private, f"{path.name} imports {private} from {node.module}"


def test_rules_module_imports_nothing_from_abco():
    tree = ast.parse((PACKAGE / "maze" / "rules.py").read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in imported if m and m.startswith("abco")}


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_wall_bits_are_named_not_written_as_numbers(path):
    if path.name == "rules.py":
        return
    code = path.read_text()
    assert not re.findall(r"&\s*[1248]\b", code), f"{path.name}: use rules.OPEN_N/E/S/W"

"""Expert-demo generators: maze expert optimality and tie-breaking, random policy, recorder."""

import gymnasium as gym
import numpy as np
import pytest

from abco_envs import MAZE_IDS, MAZE_SIZES, maze_size
from abco_envs.experts import MazeExpert, RandomPolicy, expert_policy, record_episode
from abco_envs.experts.random_policy import hold_range
from abco_envs.maze.layout import DELTAS, shortest_path_length
from abco_envs.maze.pool import layout_pool


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_expert_path_is_optimal_on_every_pool_layout(n):
    pool = layout_pool(n)
    for cells in np.concatenate([pool.train, pool.test]):
        actions = MazeExpert(cells, seed=0).solve()
        assert len(actions) == shortest_path_length(cells)
        row, col = 0, 0
        for a in actions:  # every move goes through an open side
            assert cells[row, col] & (1, 4, 2, 8)[a]
            row, col = row + DELTAS[a][0], col + DELTAS[a][1]
        assert (row, col) == (n - 1, n - 1)


def test_expert_seeds_break_ties_differently_but_reproducibly():
    pool = layout_pool(10)
    differ = 0
    for cells in pool.train[:30]:
        paths = {tuple(MazeExpert(cells, seed=s).solve()) for s in range(10)}
        assert MazeExpert(cells, seed=3).solve() == MazeExpert(cells, seed=3).solve()
        differ += len(paths) > 1
    assert differ > 0  # loops make several shortest paths on some layouts


def test_expert_from_any_start_and_at_goal():
    cells = layout_pool(5).train[0]
    expert = MazeExpert(cells, seed=0)
    assert len(expert.solve((2, 2))) == expert.dist[2, 2]
    with pytest.raises(ValueError, match="goal"):
        expert.act(4, 4)


@pytest.mark.parametrize("env_id", MAZE_IDS)
def test_expert_policy_solves_every_train_layout_through_the_env(env_id):
    n = maze_size(env_id)
    env = gym.make(env_id)
    policy = expert_policy(env_id, seed=1)
    for index in range(0, 100, 9):
        episode = record_episode(env, policy, options={"layout_index": index})
        assert episode.terminations[-1]
        assert episode.length == shortest_path_length(layout_pool(n).train[index])


def test_random_policy_is_seeded_and_uniform():
    space = gym.spaces.Discrete(3)
    a = [RandomPolicy(space, seed=5)(None, {}) for _ in range(1)]
    policy, again = RandomPolicy(space, seed=5), RandomPolicy(space, seed=5)
    draws = np.array([policy(None, {}) for _ in range(3000)])
    assert draws[0] == a[0]
    assert np.array_equal(draws[:50], [again(None, {}) for _ in range(50)])
    assert np.allclose(np.bincount(draws, minlength=3) / 3000, 1 / 3, atol=0.03)
    with pytest.raises(TypeError, match="Discrete"):
        RandomPolicy(gym.spaces.Box(0, 1, (2,)))


def _runs(actions):
    """Lengths of the runs of equal consecutive actions."""
    cuts = np.flatnonzero(np.diff(actions)) + 1
    return np.diff(np.r_[0, cuts, len(actions)])


def test_random_policy_holds_each_action():
    space = gym.spaces.Discrete(3)
    plain, one = RandomPolicy(space, seed=5), RandomPolicy(space, seed=5, hold=1)
    assert [plain(None, {}) for _ in range(40)] == [one(None, {}) for _ in range(40)]
    plain, four = RandomPolicy(space, seed=5), RandomPolicy(space, seed=5, hold=4)
    held = [four(None, {}) for _ in range(40)]
    assert held[::4] == [plain(None, {}) for _ in range(10)]  # hold=1's draws, each held
    policy, again = RandomPolicy(space, seed=7, hold=4), RandomPolicy(space, seed=7, hold=4)
    held = np.array([policy(None, {}) for _ in range(4000)])
    assert np.array_equal(held, [again(None, {}) for _ in range(4000)])
    assert np.all(held.reshape(-1, 4) == held[::4, None])  # 4 steps each, then a new draw
    assert np.allclose(np.bincount(held, minlength=3) / 4000, 1 / 3, atol=0.04)


def test_random_policy_draws_hold_lengths_in_range():
    space = gym.spaces.Discrete(3)
    policy, again = RandomPolicy(space, seed=3, hold=[2, 6]), RandomPolicy(space, seed=3,
                                                                           hold=(2, 6))
    draws = np.array([policy(None, {}) for _ in range(6000)])
    assert np.array_equal(draws, [again(None, {}) for _ in range(6000)])
    # a run of equal actions is one hold or several back to back: always at least 2 steps
    runs = _runs(draws)[:-1]  # the last run may be cut
    assert runs.min() >= 2 and set(range(2, 7)) <= set(runs.tolist())
    for bad in (0, -1, True, 2.5, [3, 2], [0, 2], [1, 2, 3], "4"):
        with pytest.raises(ValueError, match="hold"):
            RandomPolicy(space, hold=bad)
    assert hold_range(4) == (4, 4) and hold_range([1, 8]) == (1, 8)


def test_record_episode_keeps_the_final_observation_and_caps_length():
    env = gym.make("AbcoMaze10x10-v0")
    episode = record_episode(env, RandomPolicy(env.action_space, seed=0), seed=0, max_steps=25)
    assert episode.length == 25 and len(episode.observations) == 26
    assert episode.truncations[-1] and not episode.truncations[:-1].any()
    assert len(episode.positions) == 26
    # the recorded frames are the env's observations of those positions
    renderer = env.unwrapped.renderer
    last = renderer.frame(episode.layout, *episode.positions[-1])
    assert np.array_equal(last, episode.observations[-1])


def test_demo_writes_a_png(tmp_path):
    from abco_envs.demo import main

    out = tmp_path / "demo.png"
    main(["--env", "AbcoMaze5x5-v0", "--out", str(out), "--image-size", "96"])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

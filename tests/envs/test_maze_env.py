"""The maze env's contract, parametrised over every registered id."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import abco_envs
from abco_envs import MAZE_IDS, Action, InvalidLayoutError, maze_size
from abco_envs.experts import MazeExpert, record_episode
from abco_envs.maze.layout import shortest_path_length
from abco_envs.maze.pool import layout_pool


@pytest.mark.parametrize("env_id", MAZE_IDS)
@pytest.mark.parametrize(
    "kwargs", [{}, {"obs_type": "state"}, {"render_mode": "rgb_array"}, {"image_size": 224}]
)
def test_check_env_passes_without_warnings(env_id, kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, **kwargs)
        check_env(env.unwrapped, skip_render_check=False)
        env.close()


@pytest.mark.parametrize("env_id", MAZE_IDS)
def test_reachable_with_module_prefix_and_spaces(env_id):
    env = gym.make(f"abco_envs:{env_id}")
    n = maze_size(env_id)
    assert env.spec.max_episode_steps == 1000
    assert env.action_space == gym.spaces.Discrete(4)
    assert env.observation_space.shape == (64, 64, 3)
    assert env.observation_space.dtype == np.uint8
    state_env = gym.make(env_id, obs_type="state")
    assert state_env.observation_space.shape == (2 * n + 4 * n * n,)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["position"].tolist() == [0, 0]
    assert info["layout_id"] in layout_pool(n).train_ids


def test_unknown_ids_and_options_are_refused():
    with pytest.raises(gym.error.Error):
        gym.make("AbcoMaze4x4-v0")
    with pytest.raises(ValueError, match="unknown maze id"):
        maze_size("AbcoMaze4x4-v0")
    with pytest.raises(ValueError, match="obs_type"):
        gym.make("AbcoMaze3x3-v0", obs_type="pixels")
    with pytest.raises(ValueError, match="split"):
        gym.make("AbcoMaze3x3-v0", split="valid")
    with pytest.raises(ValueError, match="too small"):
        gym.make("AbcoMaze10x10-v0", image_size=8)
    env = gym.make("AbcoMaze3x3-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="invalid action"):
        env.step(4)


@pytest.mark.parametrize("env_id", MAZE_IDS)
def test_same_seed_same_episode(env_id):
    def run(seed):
        env = gym.make(env_id)
        obs, info = env.reset(seed=seed)
        frames, ids = [obs], [info["layout_id"]]
        for a in np.random.default_rng(1).integers(4, size=60):
            obs, reward, terminated, truncated, info = env.step(a)
            frames.append(obs)
            if terminated or truncated:
                obs, info = env.reset()
                ids.append(info["layout_id"])
        return np.stack(frames), ids

    a, b, c = run(3), run(3), run(4)
    assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    assert a[1][0] != c[1][0] or not np.array_equal(a[0], c[0])


def test_observations_are_fresh_arrays():
    env = gym.make("AbcoMaze5x5-v0")
    obs0, info0 = env.reset(seed=0)
    kept, pos = obs0.copy(), info0["position"].copy()
    obs1, *_, info1 = env.step(Action.S)
    obs2, *_ = env.step(Action.E)
    assert np.array_equal(obs0, kept) and np.array_equal(info0["position"], pos)
    assert obs1 is not obs2 and not np.shares_memory(obs1, obs2)
    state_env = gym.make("AbcoMaze5x5-v0", obs_type="state")
    s0, _ = state_env.reset(seed=0)
    s_kept = s0.copy()
    state_env.step(Action.S)
    assert np.array_equal(s0, s_kept)


@pytest.mark.parametrize("env_id", MAZE_IDS)
def test_expert_episode_rewards_and_termination(env_id):
    n = maze_size(env_id)
    env = gym.make(env_id)
    expert = MazeExpert(seed=0)
    episode = record_episode(env, expert, seed=11)
    length = shortest_path_length(episode.layout)
    assert episode.length == length
    assert episode.terminations[-1] and not episode.truncations.any()
    assert episode.positions[-1].tolist() == [n - 1, n - 1]
    assert np.allclose(episode.rewards[:-1], -0.1 / n**2) and episode.rewards[-1] == 1.0
    assert episode.episode_return == pytest.approx(1 - (length - 1) * 0.1 / n**2)


def test_walls_block_moves():
    env = gym.make("AbcoMaze3x3-v0")
    env.reset(seed=0)
    cells = env.unwrapped.cells
    # (0, 0) is closed to the north and west: those moves leave the agent in place.
    for a in (Action.N, Action.W):
        obs, reward, terminated, truncated, info = env.step(a)
        assert info["position"].tolist() == [0, 0] and reward == pytest.approx(-0.1 / 9)
    for a, bit in ((Action.S, 4), (Action.E, 2)):
        env.reset(options={"layout": cells})
        *_, info = env.step(a)
        moved = info["position"].tolist() != [0, 0]
        assert moved == bool(cells[0, 0] & bit)


@pytest.mark.parametrize("limit", [1, 7])
def test_truncation_exactly_at_the_limit(limit):
    env = gym.make("AbcoMaze10x10-v0", max_episode_steps=limit)
    env.reset(seed=0)
    for t in range(1, limit + 1):
        *_, terminated, truncated, _ = env.step(Action.N)  # never reaches the goal
        assert truncated == (t == limit) and not terminated


def test_explicit_layout_start_and_index():
    pool = layout_pool(5)
    env = gym.make("AbcoMaze5x5-v0")
    obs, info = env.reset(seed=0, options={"layout": pool.test[3], "start": (2, 1)})
    assert info["layout_id"] == pool.test_ids[3] and info["position"].tolist() == [2, 1]
    assert info["layout_index"] == -1
    obs, info = env.reset(options={"layout_index": 42})
    assert info["layout_id"] == pool.train_ids[42] and info["layout_index"] == 42
    bad = pool.train[0].copy()
    bad[0, 0] |= 8
    with pytest.raises(InvalidLayoutError, match="outside"):
        env.reset(options={"layout": bad})
    with pytest.raises(IndexError, match="out of range"):
        env.reset(options={"layout_index": 100})
    with pytest.raises(ValueError, match="outside"):
        env.reset(options={"start": (5, 0)})


def test_test_split_and_fresh_layouts():
    test_env = gym.make("AbcoMaze5x5-v0", split="test")
    _, info = test_env.reset(seed=0)
    assert info["layout_id"] in layout_pool(5).test_ids
    fresh = gym.make("AbcoMaze5x5-v0", split="fresh")
    _, a = fresh.reset(seed=5)
    _, b = fresh.reset(seed=5)
    assert a["layout_id"] == b["layout_id"]


def test_rendering_colours_and_sizes():
    env = gym.make("AbcoMaze5x5-v0", render_mode="rgb_array", image_size=(100, 160))
    obs, _ = env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (100, 160, 3) and np.array_equal(frame, obs)
    colours = {tuple(c) for c in obs.reshape(-1, 3)}
    from abco_envs.maze.render import AGENT, FLOOR, GOAL, START, WALL

    assert {tuple(FLOOR), tuple(WALL), tuple(START), tuple(GOAL), tuple(AGENT)} <= colours
    assert tuple(obs[-10, -10]) == tuple(GOAL)  # goal cell bottom-right
    small = gym.make("AbcoMaze10x10-v0", image_size=20)
    assert small.reset(seed=0)[0].shape == (20, 20, 3)


def test_state_observation_encodes_position_and_walls():
    env = gym.make("AbcoMaze3x3-v0", obs_type="state")
    obs, info = env.reset(seed=0, options={"start": (1, 2)})
    cells = env.unwrapped.cells
    assert obs[:3].tolist() == [0, 1, 0] and obs[3:6].tolist() == [0, 0, 1]
    walls = obs[6:].reshape(3, 3, 4)
    assert walls[0, 0, Action.S] == bool(cells[0, 0] & 4)
    assert walls[0, 0, Action.E] == bool(cells[0, 0] & 2)


@pytest.mark.parametrize("env_id", MAZE_IDS)
def test_pickling_keeps_the_episode(env_id):
    env = gym.make(env_id)
    env.reset(seed=2)
    env.step(Action.S)
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(Action.E)
    b = clone.step(Action.E)
    assert np.array_equal(a[0], b[0]) and a[1:4] == b[1:4]


@pytest.mark.filterwarnings("ignore:.*matplotlib is not installed")  # play() probes TkAgg
def test_human_mode_and_play_work_headless(monkeypatch):
    pygame = pytest.importorskip("pygame")
    from gymnasium.utils import play

    env = gym.make("AbcoMaze3x3-v0", render_mode="human")
    env.reset(seed=0)
    env.step(Action.S)
    env.close()
    keys = gym.make("AbcoMaze3x3-v0").unwrapped.get_keys_to_action()
    assert keys[(pygame.K_UP,)] == Action.N and keys[(pygame.K_LEFT,)] == Action.W

    calls = {"n": 0}

    def fake_events():
        calls["n"] += 1
        return [pygame.event.Event(pygame.QUIT)] if calls["n"] > 3 else []

    monkeypatch.setattr(pygame.event, "get", fake_events)
    play.play(gym.make("AbcoMaze3x3-v0", render_mode="rgb_array"), fps=1000)
    assert calls["n"] > 3


def test_import_is_light():
    import subprocess
    import sys

    code = "import abco_envs, sys; print('torch' in sys.modules, 'pygame' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    assert abco_envs.__version__

"""abco_data against Minari on the same maze frames, in one run.

Measures, on identical episodes of 64x64 RGB maze frames (random walks in AbcoMaze10x10-v0):

- write: every transition pushed through a replay env, collected and written to disk: abco's
  :class:`~abco_data.format.DatasetWriter` vs Minari's ``DataCollector`` + ``create_dataset``
  (default JPEG frames, and lossless ``jpeg_encoding=False``);
- read every transition as ``(s, a, s')`` arrays: abco ``load_arrays`` + ``transition_index``
  vs Minari ``iterate_episodes``;
- sample 1,000 random transitions from the file: abco ``read_transitions`` vs Minari
  (each needed episode read once);
- peak memory (tracemalloc) of the full read, against the raw bytes of the arrays.

Goals (issue 3): write and read at least 20x Minari's; loading into memory costs at most 1.2x
the raw array bytes.

Usage: ``python benchmarks/bench_data.py [--episodes 1000] [--steps 10]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import abco_envs  # noqa: F401
from abco_data.dataset import open_dataset
from abco_data.format import DatasetWriter, space_to_json


class ReplayEnv(gym.Env):
    """Replays recorded episodes, so both writers see identical frames at no render cost."""

    def __init__(self, episodes: list[dict[str, np.ndarray]], obs_space: Any, act_space: Any):
        self.episodes, self.observation_space, self.action_space = episodes, obs_space, act_space
        self.e, self.t = -1, 0

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        self.e, self.t = self.e + 1, 0
        return self.episodes[self.e]["obs"][0], {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        ep, self.t = self.episodes[self.e], self.t + 1
        last = self.t == len(ep["act"])
        return ep["obs"][self.t], float(ep["rew"][self.t - 1]), bool(ep["term"][self.t - 1]), \
            last and not ep["term"][self.t - 1], {}


def record(n_episodes: int, steps: int) -> tuple[list[dict[str, np.ndarray]], Any, Any]:
    env = gym.make("AbcoMaze10x10-v0", max_episode_steps=steps)
    rng = np.random.default_rng(0)
    episodes = []
    for i in range(n_episodes):
        obs, _ = env.reset(seed=i, options={"start": tuple(rng.integers(9, size=2))})
        frames, acts, rews, terms = [obs], [], [], []
        done = False
        while not done:
            a = int(rng.integers(4))
            obs, r, term, trunc, _ = env.step(a)
            frames.append(obs), acts.append(a), rews.append(r), terms.append(term)
            done = term or trunc
        episodes.append({"obs": np.stack(frames), "act": np.array(acts), "rew": np.array(rews),
                         "term": np.array(terms)})
    return episodes, env.observation_space, env.action_space


def abco_write(replay: ReplayEnv, n_episodes: int, path: Path) -> None:
    lengths = []
    with DatasetWriter(path) as w:
        for _ in range(n_episodes):
            obs, _ = replay.reset()
            frames, acts, rews, terms, truncs = [obs], [], [], [], []
            done = False
            while not done:
                a = replay.episodes[replay.e]["act"][replay.t]
                obs, r, term, trunc, _ = replay.step(a)
                frames.append(obs), acts.append(a), rews.append(r)
                terms.append(term), truncs.append(trunc)
                done = term or trunc
            w.append("observations", np.stack(frames))
            w.append("actions", np.asarray(acts, dtype=np.int64))
            w.append("rewards", np.asarray(rews))
            w.append("terminations", np.asarray(terms))
            w.append("truncations", np.asarray(truncs))
            lengths.append(len(acts))
        lengths = np.asarray(lengths, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        for key, value in (("obs_offset", starts + np.arange(len(lengths))),
                           ("transition_offset", starts), ("length", lengths),
                           ("seed", np.arange(len(lengths))), ("return", np.zeros(len(lengths)))):
            w.append(f"episodes/{key}", value)
        n_tr = int(lengths.sum())
        w.attrs.update({
            "format": "abco-dataset", "format_version": 1, "dataset_id": "bench/maze-v0",
            "kind": "pre_demonstrations", "env_id": "AbcoMaze10x10-v0", "env_spec": "{}",
            "env_kwargs": "{}", "observation_space": space_to_json(replay.observation_space),
            "action_space": space_to_json(replay.action_space), "generator": "bench",
            "generator_version": 1, "seed": 0, "num_episodes": len(lengths),
            "num_transitions": n_tr, "num_observations": n_tr + len(lengths),
            "creation_params": "{}", "reference_expert_mean": 1.0,
            "reference_random_mean": 0.0})


def minari_write(replay: ReplayEnv, n_episodes: int, root: Path, name: str, jpeg: bool) -> Any:
    import minari

    os.environ["MINARI_DATASETS_PATH"] = str(root)
    collector = minari.DataCollector(replay, jpeg_encoding=jpeg)
    for _ in range(n_episodes):
        collector.reset()
        done = False
        while not done:
            a = replay.episodes[replay.e]["act"][replay.t]
            _, _, term, trunc, _ = collector.step(a)
            done = term or trunc
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return collector.create_dataset(name, algorithm_name="random", author="bench",
                                        author_email="-", code_permalink="-", description="-")


def best(repeats: int, fn: Any) -> float:
    """Best (lowest) wall time of ``fn(i)`` over ``repeats`` runs, as ``timeit`` reports."""
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - start)
    return min(times)


def peak(fn: Any) -> tuple[int, Any]:
    tracemalloc.start()
    out = fn()
    _, high = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return high, out


def abco_read_all(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every transition as arrays (``s'`` rows are views of the one observations array)."""
    ds = open_dataset(path)
    a = ds.load_arrays()
    obs_t, obs_t1 = ds.transition_index()
    ds.close()
    return a.observations, obs_t, a.actions


def minari_read_all(m: Any) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    return [(ep.observations[:-1], ep.actions, ep.observations[1:])
            for ep in m.iterate_episodes()]


def minari_sample(m: Any, rng: np.random.Generator, k: int) -> list[Any]:
    lengths = np.array([len(ep.actions) for ep in m.iterate_episodes()]) if not hasattr(
        m, "_bench_lengths") else m._bench_lengths
    m._bench_lengths = lengths
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    picks = rng.integers(lengths.sum(), size=k)
    ep_of = np.searchsorted(starts, picks, side="right") - 1
    out = []
    wanted = np.unique(ep_of)
    for e, ep in zip(wanted, m.iterate_episodes(episode_indices=wanted)):
        for p in picks[ep_of == e]:
            t = p - starts[e]
            out.append((ep.observations[t], ep.actions[t], ep.observations[t + 1]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3, help="best of this many runs")
    parser.add_argument("--steps", type=int, default=10,
                        help="episode cap (10: the maze pre-demonstrations' episodes)")
    args = parser.parse_args()
    episodes, obs_space, act_space = record(args.episodes, args.steps)
    n_tr = sum(len(e["act"]) for e in episodes)
    raw = sum(e["obs"].nbytes for e in episodes)
    print(f"{args.episodes} episodes, {n_tr} transitions, {raw / 1e6:.1f} MB of raw frames\n")
    tmp = Path(tempfile.mkdtemp(prefix="bench_data_"))
    n = args.episodes

    reps = args.repeats
    t_abco = best(reps, lambda i: abco_write(ReplayEnv(episodes, obs_space, act_space), n,
                                             tmp / f"abco{i}.hdf5"))
    made: dict[str, Any] = {}

    def mw(i: int, jpeg: bool) -> None:
        name = f"bench/{'jpeg' if jpeg else 'raw'}{i}-v0"
        made[str(jpeg)] = minari_write(ReplayEnv(episodes, obs_space, act_space), n,
                                       tmp / "minari", name, jpeg)

    t_mj = best(reps, lambda i: mw(i, True))
    t_ml = best(reps, lambda i: mw(i, False))
    m_jpeg, m_raw = made["True"], made["False"]
    abco_size = (tmp / "abco0.hdf5").stat().st_size
    rows = [("write", "transitions/s", n_tr / t_abco, n_tr / t_mj, n_tr / t_ml)]

    r_abco = best(reps, lambda i: abco_read_all(tmp / "abco0.hdf5"))
    r_mj = best(reps, lambda i: minari_read_all(m_jpeg))
    r_ml = best(reps, lambda i: minari_read_all(m_raw))
    rows.append(("read every transition", "transitions/s", n_tr / r_abco, n_tr / r_mj,
                 n_tr / r_ml))

    ds = open_dataset(tmp / "abco0.hdf5")
    rng = np.random.default_rng(1)
    ds.read_transitions(rng.integers(n_tr, size=10))  # open the handle, as a loader would
    s_abco = best(reps, lambda i: ds.read_transitions(rng.integers(n_tr, size=1000)))
    minari_sample(m_jpeg, rng, 10), minari_sample(m_raw, rng, 10)
    s_mj = best(reps, lambda i: minari_sample(m_jpeg, rng, 1000))
    s_ml = best(reps, lambda i: minari_sample(m_raw, rng, 1000))
    rows.append(("sample 1,000 transitions", "ms", s_abco * 1e3, s_mj * 1e3, s_ml * 1e3))

    p_abco, _ = peak(lambda: abco_read_all(tmp / "abco0.hdf5"))
    arrays = peak(lambda: ds.load_arrays())
    p_mj, _ = peak(lambda: minari_read_all(m_jpeg))
    p_ml, _ = peak(lambda: minari_read_all(m_raw))
    rows.append(("peak memory, read all", "MB", p_abco / 1e6, p_mj / 1e6, p_ml / 1e6))

    print(f"{'':26}{'unit':>15}{'abco':>12}{'minari jpeg':>14}{'minari raw':>13}"
          f"{'x jpeg':>9}{'x raw':>8}")
    for name, unit, a, mj, ml in rows:
        x_j, x_r = (a / mj, a / ml) if unit == "transitions/s" else (mj / a, ml / a)
        print(f"{name:26}{unit:>15}{a:12.1f}{mj:14.1f}{ml:13.1f}{x_j:9.1f}{x_r:8.1f}")
    minari_size = sum(f.stat().st_size for f in (tmp / "minari").rglob("*.hdf5"))
    print(f"\nfile sizes: abco {abco_size / 1e6:.2f} MB (lossless), minari jpeg + raw"
          f" {minari_size / 1e6:.2f} MB together")
    load_peak, a = arrays
    print(f"load_arrays: peak {load_peak / 1e6:.1f} MB for {a.nbytes / 1e6:.1f} MB of arrays"
          f" = {load_peak / a.nbytes:.3f}x raw (goal <= 1.2x)")
    write_ok = rows[0][2] / rows[0][3] >= 20
    read_ok = rows[1][2] / rows[1][3] >= 20
    print(f"goals: write >= 20x minari: {'met' if write_ok else 'NOT met'};"
          f" read >= 20x minari: {'met' if read_ok else 'NOT met'};"
          f" memory <= 1.2x: {'met' if load_peak <= 1.2 * a.nbytes else 'NOT met'}")
    ds.close()
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

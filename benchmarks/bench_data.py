"""abco_data against Minari (its lossless mode and its lossy JPEG default), in one run.

Measures, on identical episodes of 64x64 RGB maze frames (random walks in AbcoMaze10x10-v0):

- write: every transition pushed through a replay env, collected and written to disk: abco's
  :class:`~abco_data.format.DatasetWriter` (lossless 4-bit palette indices, gzip-3) vs Minari's
  ``DataCollector`` + ``create_dataset`` on HDF5, both ways Minari stores image frames:
  ``jpeg_encoding=False`` (lossless: raw uint8 frames, uncompressed; the fair peer for lossless
  frames) and its default ``jpeg_encoding=True`` (lossy: PIL JPEG, quality 75);
- read every transition as ``(s, a, s')`` arrays: abco ``open_dataset`` + ``load_arrays`` +
  ``transition_index`` vs Minari ``iterate_episodes``;
- sample random transitions from the file: abco ``read_transitions`` vs Minari (each needed
  episode read once);
- peak memory (tracemalloc) of the full read, against the raw bytes of the arrays.

Goals: write and read at least 20x Minari's lossless mode;
loading into memory costs at most 1.2x the raw array bytes. Figures are the best of
``--repeats`` runs of each side; the ratios compare runs made in the same process, minutes
apart, so they hold up better than the absolute figures on a loaded machine.

Minari's ``DataCollector`` needs jax: ``pip install -e ".[bench]"`` installs ``minari[create]``.

Usage: ``python benchmarks/bench_data.py [--episodes 1000] [--steps 10] [--repeats 3]``;
``--tiny`` runs in seconds (20 episodes, one repeat): a smoke test, not a measurement.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
import tracemalloc
import warnings
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import gymnasium as gym
import h5py
import numpy as np

import abco_envs  # noqa: F401
from abco_data.dataset import open_dataset
from abco_data.format import DatasetWriter, space_to_json

#: The two Minari peers: label -> ``jpeg_encoding``, and how each stores frames.
PEERS = {"minari lossless": False, "minari jpeg": True}
PEER_SETTINGS = {
    "minari lossless": "HDF5, jpeg_encoding=False: raw uint8 frames, uncompressed (lossless)",
    "minari jpeg": "HDF5, jpeg_encoding=True (the default): PIL JPEG quality 75 (lossy)",
}
#: The ratio every goal is judged on (the lossless peer), and the goal itself.
GOAL_PEER, GOAL = "minari lossless", 20.0


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
    """Random-walk episodes of at most ``steps`` steps: frames, actions, rewards, ends."""
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
    """Collect every transition of ``replay`` and write an abco dataset file."""
    lengths, returns = [], []
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
            returns.append(float(np.sum(np.asarray(rews))))
        lengths = np.asarray(lengths, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        for key, value in (("obs_offset", starts + np.arange(len(lengths))),
                           ("transition_offset", starts), ("length", lengths),
                           ("seed", np.arange(len(lengths))), ("return", np.asarray(returns))):
            w.append(f"episodes/{key}", value)
        n_tr = int(lengths.sum())
        # Its registry id's env and kind (open_dataset refuses ids it cannot place); the bytes
        # differ from the published file's, so nothing here passes for the real dataset.
        w.attrs.update({
            "format": "abco-dataset", "format_version": 1, "dataset_id": "abco/maze10x10-pre-v0",
            "kind": "pre_demonstrations", "env_id": "AbcoMaze10x10-v0", "env_spec": "{}",
            "env_kwargs": "{}", "observation_space": space_to_json(replay.observation_space),
            "action_space": space_to_json(replay.action_space), "generator": "bench",
            "generator_version": 1, "seed": 0, "num_episodes": len(lengths),
            "num_transitions": n_tr, "num_observations": n_tr + len(lengths),
            "creation_params": "{}", "reference_expert_mean": 1.0,
            "reference_random_mean": 0.0})


def minari_write(replay: ReplayEnv, n_episodes: int, root: Path, name: str, jpeg: bool) -> Any:
    """Collect every transition of ``replay`` with Minari's ``DataCollector``; the dataset."""
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


def best(repeats: int, fn: Callable[[int], Any]) -> float:
    """Best (lowest) wall time of ``fn(i)`` over ``repeats`` runs, as ``timeit`` reports."""
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - start)
    return min(times)


def peak(fn: Callable[[], Any]) -> tuple[int, Any]:
    """Peak traced memory of ``fn()`` in bytes, and its result."""
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
    """Every transition of Minari dataset ``m`` as per-episode ``(s, a, s')`` arrays."""
    return [(ep.observations[:-1], ep.actions, ep.observations[1:])
            for ep in m.iterate_episodes()]


def minari_sample(m: Any, lengths: np.ndarray, rng: np.random.Generator,
                  k: int) -> list[Any]:
    """``k`` random transitions of ``m`` (episode lengths ``lengths``), each episode read once."""
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


def versions() -> str:
    """The versions that matter to these figures."""
    names = ("numpy", "h5py", "gymnasium", "minari", "jax", "Pillow")
    found = []
    for name in names:
        try:
            found.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            found.append(f"{name} -")
    return (f"python {platform.python_version()}, {', '.join(found)},"
            f" HDF5 {h5py.version.hdf5_version}")


def machine() -> str:
    """Cores and load average now (other jobs on the machine skew every figure)."""
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"{platform.machine()}, {os.cpu_count()} cores, load average {load}"


def peer_missing() -> str | None:
    """Why Minari's ``DataCollector`` cannot run here, or None."""
    try:
        import jax  # noqa: F401
        import minari  # noqa: F401
    except ImportError as err:
        return f"{err.name} is not installed: pip install -e \".[bench]\" (minari[create])"
    return None


def main() -> int:
    """Run the benchmark and print the table; exit code 2 when Minari cannot run."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3, help="best of this many runs")
    parser.add_argument("--steps", type=int, default=10,
                        help="episode cap (10: the maze pre-demonstrations' episodes)")
    parser.add_argument("--sample", type=int, default=1000,
                        help="transitions per random sample")
    parser.add_argument("--tiny", action="store_true",
                        help="20 episodes, 1 repeat, samples of 100: runs in seconds")
    args = parser.parse_args()
    if args.tiny:
        args.episodes, args.repeats, args.sample = 20, 1, 100
    missing = peer_missing()
    if missing:
        print(f"bench_data: Minari's DataCollector cannot run: {missing}", file=sys.stderr)
        return 2
    print(versions())
    print(f"machine: {machine()} (at start)")
    for label, settings in PEER_SETTINGS.items():
        print(f"peer {label!r}: {settings}")
    episodes, obs_space, act_space = record(args.episodes, args.steps)
    n_tr = sum(len(e["act"]) for e in episodes)
    raw = sum(e["obs"].nbytes for e in episodes)
    print(f"{args.episodes} episodes, {n_tr} transitions, {raw / 1e6:.1f} MB of raw frames;"
          f" best of {args.repeats}\n")
    tmp = Path(tempfile.mkdtemp(prefix="bench_data_"))
    try:
        exact = run(args, episodes, obs_space, act_space, n_tr, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"machine: {machine()} (at end)")
    return 0 if exact else 1


def run(args: argparse.Namespace, episodes: list[dict[str, np.ndarray]], obs_space: Any,
        act_space: Any, n_tr: int, tmp: Path) -> bool:
    """Measure, print the table and the goals; whether abco read back the exact frames."""
    n, reps = args.episodes, args.repeats
    abco_path = tmp / "abco0.hdf5"
    figures: dict[str, dict[str, float]] = {}  # operation -> side -> figure

    t_abco = best(reps, lambda i: abco_write(ReplayEnv(episodes, obs_space, act_space), n,
                                             tmp / f"abco{i}.hdf5"))
    made: dict[str, Any] = {}
    write = {"abco": n_tr / t_abco}
    for label, jpeg in PEERS.items():
        def mw(i: int, label: str = label, jpeg: bool = jpeg) -> None:
            name = f"bench/{label.split()[1]}{i}-v0"
            made[label] = minari_write(ReplayEnv(episodes, obs_space, act_space), n,
                                       tmp / "minari", name, jpeg)
        write[label] = n_tr / best(reps, mw)
    figures["write (collect + create)"] = write

    read = {"abco": n_tr / best(reps, lambda i: abco_read_all(abco_path))}
    for label in PEERS:
        read[label] = n_tr / best(reps, lambda i, m=made[label]: minari_read_all(m))
    figures["read every transition"] = read

    ds = open_dataset(abco_path)
    rng = np.random.default_rng(1)
    ds.read_transitions(rng.integers(n_tr, size=10))  # open the handle, as a loader would
    sample = {"abco": 1e3 * best(reps, lambda i: ds.read_transitions(
        rng.integers(n_tr, size=args.sample)))}
    lengths = np.array([len(e["act"]) for e in episodes])
    for label in PEERS:
        m = made[label]
        minari_sample(m, lengths, rng, 10)
        sample[label] = 1e3 * best(reps, lambda i, m=m: minari_sample(m, lengths, rng,
                                                                      args.sample))
    figures[f"sample {args.sample:,} transitions"] = sample

    memory = {"abco": peak(lambda: abco_read_all(abco_path))[0] / 1e6}
    for label in PEERS:
        memory[label] = peak(lambda m=made[label]: minari_read_all(m))[0] / 1e6
    load_peak, arrays = peak(lambda: ds.load_arrays())
    exact = np.array_equal(arrays.observations,
                           np.concatenate([e["obs"] for e in episodes]))
    ds.close()

    units = {"write (collect + create)": "transitions/s", "read every transition":
             "transitions/s", f"sample {args.sample:,} transitions": "ms"}
    labels = list(PEERS)
    print(f"{'operation':<28}{'unit':>14}{'abco':>12}" + "".join(f"{p:>17}" for p in labels)
          + "".join(f"{'x ' + p.split()[1]:>12}" for p in labels))
    ratios: dict[str, dict[str, float]] = {}
    for op, fig in figures.items():
        rate = units[op] != "ms"
        ratios[op] = {p: fig["abco"] / fig[p] if rate else fig[p] / fig["abco"] for p in labels}
        print(f"{op:<28}{units[op]:>14}{fig['abco']:12,.1f}"
              + "".join(f"{fig[p]:17,.1f}" for p in labels)
              + "".join(f"{ratios[op][p]:11.1f}x" for p in labels))
    print(f"{'peak memory, read all':<28}{'MB':>14}{memory['abco']:12,.1f}"
          + "".join(f"{memory[p]:17,.1f}" for p in labels))

    abco_size = abco_path.stat().st_size
    sizes = {label: sum(f.stat().st_size for f in (tmp / "minari").rglob("*.hdf5")
                        if f"/{label.split()[1]}0-v0/" in f.as_posix()) for label in labels}
    print(f"\nfile sizes: abco {abco_size / 1e6:.2f} MB (lossless, palette4), "
          + ", ".join(f"{p} {s / 1e6:.2f} MB" for p, s in sizes.items()))
    print(f"abco read back the recorded frames bit for bit: {'yes' if exact else 'NO'}")
    print(f"load_arrays: peak {load_peak / 1e6:.1f} MB for {arrays.nbytes / 1e6:.1f} MB of arrays"
          f" = {load_peak / arrays.nbytes:.3f}x raw (goal <= 1.2x)")
    goals = [f"{op.split(' (')[0]} >= {GOAL:.0f}x {GOAL_PEER}:"
             f" {'met' if ratios[op][GOAL_PEER] >= GOAL else 'NOT met'}"
             f" ({ratios[op][GOAL_PEER]:.1f}x; {ratios[op]['minari jpeg']:.1f}x minari jpeg)"
             for op in list(figures)[:2]]
    goals.append(f"memory <= 1.2x: {'met' if load_peak <= 1.2 * arrays.nbytes else 'NOT met'}")
    print("goals: " + "; ".join(goals))
    if args.tiny:
        print("(--tiny: a smoke test; the figures mean nothing at this size)")
    return exact


if __name__ == "__main__":
    raise SystemExit(main())

"""Stepping speed of the abco mazes against Minigrid's full-RGB observations, in one run.

Random actions; single env through ``gym.make`` (all default wrappers, auto-reset by hand) and
the native vector env through ``gym.make_vec(..., vectorization_mode="vector_entry_point")``.
The peer is Minigrid with ``RGBImgObsWrapper`` on an 8x8 grid with 8-pixel tiles (64x64 RGB).

Run: ``python benchmarks/bench_envs.py [--seconds 2] [--num-envs 256]``; ``--tiny`` runs in
seconds (a smoke test: 0.01 s per figure, 8 envs, steps timed 64 at a time).
Goals: single maze env at 64x64 >= 30x Minigrid; vector env >= 500k frames/s at 256.
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import numpy as np

import abco_envs


def single_env_rate(env: gym.Env, seconds: float, block: int = 2048) -> float:
    """Steps per second of a random policy, resetting at episode ends.

    Steps go ``block`` at a time between looks at the clock.
    """
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(env.action_space.n, size=1 << 16)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for a in actions[:block]:
            _, _, terminated, truncated, _ = env.step(int(a))
            if terminated or truncated:
                env.reset()
        steps += block
        actions = np.roll(actions, block)
    return steps / (time.perf_counter() - start)


def vector_env_rate(env_id: str, num_envs: int, seconds: float, block: int = 64,
                    **kwargs) -> float:
    """Frames per second (env steps summed over the batch) of the native vector env.

    Batched steps go ``block`` at a time between looks at the clock.
    """
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)
    envs.reset(seed=0)
    actions = np.random.default_rng(0).integers(4, size=(block, num_envs))
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for a in actions:
            envs.step(a)
        calls += len(actions)
    return calls * num_envs / (time.perf_counter() - start)


def minigrid_rate(seconds: float, block: int = 2048) -> float | None:
    """Minigrid full-RGB (64x64) single-env steps per second, or None if not installed."""
    try:
        import minigrid  # noqa: F401
        from minigrid.wrappers import RGBImgObsWrapper
    except ImportError:
        return None
    env = RGBImgObsWrapper(gym.make("MiniGrid-Empty-8x8-v0"), tile_size=8)
    assert env.observation_space["image"].shape == (64, 64, 3)
    return single_env_rate(env, seconds, block)


def main() -> None:
    """Print one table: steps/s and ratio to Minigrid for every maze size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--tiny", action="store_true",
                        help="0.01 s per figure, 8 envs, small blocks: a smoke test")
    args = parser.parse_args()
    block, vector_block = 2048, 64
    if args.tiny:
        args.seconds, args.num_envs, block, vector_block = 0.01, 8, 64, 4
    print(f"machine: {platform.machine()} {platform.processor() or ''} python "
          f"{platform.python_version()}, numpy {np.__version__}, gymnasium {gym.__version__}")
    peer = minigrid_rate(args.seconds, block)
    print(f"Minigrid-Empty-8x8 + RGBImgObsWrapper (64x64): "
          f"{peer:,.0f} steps/s" if peer else "minigrid not installed: no ratio")
    header = f"{'env':<20}{'obs':<10}{'single steps/s':>16}{'x Minigrid':>12}"
    header += f"{'vector frames/s':>18}{'x Minigrid':>12}"
    print(header)
    for env_id in abco_envs.MAZE_IDS:
        for label, kwargs in (("64x64", {}), ("224x224", {"image_size": 224}),
                              ("state", {"obs_type": "state"})):
            single = single_env_rate(gym.make(env_id, **kwargs), args.seconds, block)
            vector = vector_env_rate(env_id, args.num_envs, args.seconds, vector_block,
                                     **kwargs)
            ratio = (lambda v: f"{v / peer:>11.1f}x") if peer else (lambda v: f"{'-':>12}")
            print(f"{env_id:<20}{label:<10}{single:>16,.0f}{ratio(single)}"
                  f"{vector:>18,.0f}{ratio(vector)}")


if __name__ == "__main__":
    main()

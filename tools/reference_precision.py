"""How precise a classic-control dataset's score references are: their standard errors.

The score is ``(R - R_random) / (R_expert - R_random)``; each reference is a mean over seeded
episodes (:func:`abco_data.classic_reference`), so its standard error is the spread of the
returns over the square root of the episodes. This script replays the reference episodes of
the datasets it is given (the same seeds and policies as their generation) and prints, per
dataset, each reference's mean, standard deviation, standard error and that error as a share
of the scale, against the goal of 0.01.

Usage::

    .venv/bin/python tools/reference_precision.py                       # every classic expert set
    .venv/bin/python tools/reference_precision.py abco/lunarlander-expert-v0
"""

from __future__ import annotations

import argparse
import sys

import gymnasium as gym
import numpy as np

import abco_data
from abco_data.generation.reference import REFERENCE_SEED
from abco_envs.experts import RandomPolicy, expert_policy

#: A reference's standard error, as a share of the score's scale, that the datasets meet.
GOAL = 0.01
#: The classic-control expert datasets (both versions).
DEFAULT = [i for i in abco_data.DATASET_IDS if "-expert-" in i and not i.startswith("abco/maze")]


def returns(env_id: str, policy_for_episode, episodes: int, seed: int) -> np.ndarray:
    """Each episode's return, as :func:`abco_data.classic_reference` plays them."""
    env, out = gym.make(env_id), []
    for i in range(episodes):
        policy = policy_for_episode(env, seed + i)
        obs, info = env.reset(seed=seed + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            total, done = total + float(reward), terminated or truncated
        out.append(total)
    env.close()
    return np.asarray(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("ids", nargs="*", default=DEFAULT, help="classic-control dataset ids")
    args = parser.parse_args(argv)
    print(f"{'dataset':32} {'reference':9} {'episodes':>8} {'mean':>9} {'std':>8} {'se':>7}"
          f" {'se/scale':>9}  goal {GOAL}")  # fmt: skip
    for ds_id in args.ids:
        s = abco_data.spec(ds_id)
        env_id, p = s.env_id, s.params
        random = returns(env_id, lambda env, i: RandomPolicy(env.action_space, seed=i),
                         p["reference_episodes"], REFERENCE_SEED)  # fmt: skip
        expert = returns(env_id, lambda env, i, e=env_id: expert_policy(e, seed=i),
                         p["reference_expert_episodes"], REFERENCE_SEED + 10_000)  # fmt: skip
        scale = expert.mean() - random.mean()
        for name, r in (("random", random), ("expert", expert)):
            se = r.std(ddof=1) / np.sqrt(len(r)) if len(r) > 1 else float("nan")
            verdict = "met" if se / abs(scale) < GOAL else "missed"
            print(f"{ds_id:32} {name:9} {len(r):8d} {r.mean():9.2f} {r.std(ddof=1):8.2f}"
                  f" {se:7.3f} {se / abs(scale):9.4f}  {verdict}")  # fmt: skip
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

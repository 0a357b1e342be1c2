"""Training-free expert controllers for Gymnasium's classic-control tasks and LunarLander.

CartPole's, Acrobot's and MountainCar's are hand-written here; LunarLander-v3's is Gymnasium's
own heuristic lander (:mod:`abco_envs.experts.lunar_lander`, with its figures).

Each controller is a pure, deterministic function of the current observation (no hidden
state, no randomness, no learned weights). The constants were tuned offline by a small
grid / hill-climbing search on a re-implementation of the dynamics and are hard-coded here.

Measured with :func:`rollout_returns` (100 episodes, ``reset(seed=k)`` for k = 0..99,
default time limits, gymnasium 1.4.0):

==============  ========  =====  =====
env id          mean      min    max
==============  ========  =====  =====
CartPole-v1     500.00    500    500
MountainCar-v0  -98.67    -112   -83
Acrobot-v1      -71.75    -109   -62
LunarLander-v3  252.83    -190   320
==============  ========  =====  =====

On 1000 unseen seeds (1000..1999) the figures are similar: CartPole 500 in every episode,
MountainCar mean -99.9 (worst -112), Acrobot mean -70.8 (with a rare slow episode, worst -191).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import gymnasium as gym
import numpy as np

from abco_envs.dependencies import check_env_dependencies
from abco_envs.errors import UnknownEnvError
from abco_envs.experts.lunar_lander import lunar_lander_action
from abco_envs.ids import env_name

__all__ = [
    "CONTROLLERS",
    "acrobot_action",
    "cartpole_action",
    "controller_for",
    "mountaincar_action",
    "rollout_returns",
]

# CartPole gains: u = K . [x, x_dot, theta, theta_dot]; push right iff u > 0.
_CP_GAINS = (0.1, 0.5, 1.0, 0.5)

# MountainCar switching curve (see ``mountaincar_action``).
_MC_PIVOT = -0.45  # position where the switching curve changes shape
_MC_RIGHT_SLOPE = 0.3  # slope of the "turn back early" branch right of the pivot
_MC_RIGHT_CAP = 0.015  # cap on that branch so the final run to the flag is never braked
_MC_LEFT_SLOPE = 0.015  # slope of the "reverse early" branch left of the pivot

# Acrobot switching function coefficients (see ``acrobot_action``).
_AC_THETA1 = 1.9
_AC_DTHETA1 = 0.67
_AC_DTHETA1_SQ = 0.5


def cartpole_action(obs: np.ndarray) -> int:
    """Bang-bang linear state feedback for CartPole.

    Args:
        obs: Observation ``[x, x_dot, theta, theta_dot]``.

    Returns:
        ``1`` (push right) or ``0`` (push left).
    """
    # Why it works: ``theta + 0.5 * theta_dot`` is a short look-ahead of the pole tilt, and
    # pushing the cart towards the side the pole is falling moves the pivot back under the
    # centre of mass. The small position/velocity terms have the same sign as the tilt terms
    # (as in an LQR gain): to bring the cart back to the centre the controller first has to
    # lean the pole towards the centre, which it does by briefly pushing *away* from it. Without
    # them the cart drifts to |x| ~ 2.36 (limit 2.4); with them |x| stays below ~0.13.
    x, x_dot, theta, theta_dot = (float(v) for v in obs[:4])
    kx, kv, kt, kw = _CP_GAINS
    u = kx * x + kv * x_dot + kt * theta + kw * theta_dot
    return 1 if u > 0.0 else 0


def acrobot_action(obs: np.ndarray) -> int:
    """Phase-shifted bang-bang energy pumping for Acrobot.

    Args:
        obs: Observation ``[cos t1, sin t1, cos t2, sin t2, dt1, dt2]``.

    Returns:
        ``2`` (torque +1), or ``0`` (torque -1); the zero-torque action is never used.
    """
    # Why it works: the only actuator is the elbow, and the rate at which it adds mechanical
    # energy is exactly ``torque * dt2``, so ``sign(dt2)`` pumps energy as fast as possible
    # (mean ~ -84 on its own). Reaching the target height quickly also needs the right *phase*:
    # the ``t1`` term advances the switch so the elbow folds in the direction the first link is
    # already displaced, like a gymnast kicking at the end of each swing, and the ``dt1`` term
    # feeds the shoulder motion into the elbow while the swing is slow but reverses sign once
    # |dt1| > 1.34 rad/s, braking the elbow relative to the shoulder so the energy is whipped
    # out into the tip of the second link. Coefficients tuned by hill-climbing.
    c1, s1, _, _, dt1, dt2 = (float(v) for v in obs[:6])
    theta1 = math.atan2(s1, c1)
    u = dt2 + _AC_THETA1 * theta1 + dt1 * (_AC_DTHETA1 - _AC_DTHETA1_SQ * abs(dt1))
    return 2 if u > 0.0 else 0


def mountaincar_action(obs: np.ndarray) -> int:
    """Velocity-following bang-bang control with an early-reversal switching curve.

    Args:
        obs: Observation ``[position, velocity]``.

    Returns:
        ``2`` (push right) or ``0`` (push left); the no-push action is never used.
    """
    # Why it works: the engine's power is force * velocity, so pushing in the direction of
    # motion pumps energy into the oscillation at the maximal rate. Pure ``sign(v)`` scores
    # ~ -120, because (a) the first swing to the right from the valley is only a wind-up, so
    # climbing it until the car stops wastes time, and (b) on the left slope the car should
    # turn around as soon as it has enough energy rather than coast to its apex. The switching
    # curve ``v > s(x)`` encodes both: right of the pivot s(x) > 0 (turn back early when moving
    # right too slowly to make it; capped so the final dash is never braked), left of the pivot
    # s(x) < 0 (start pushing right while still drifting slowly left). At reset (v = 0) it also
    # picks the better first direction: right if x < -0.45, else left. Scores ~ -98.7 vs ~ -97.1
    # for a value-iteration optimum on the same 100 starts.
    x, v = float(obs[0]), float(obs[1])
    if x > _MC_PIVOT:
        threshold = min(_MC_RIGHT_SLOPE * (x - _MC_PIVOT), _MC_RIGHT_CAP)
    else:
        threshold = _MC_LEFT_SLOPE * (x - _MC_PIVOT)
    return 2 if v > threshold else 0


CONTROLLERS: dict[str, Callable[[np.ndarray], int]] = {
    "CartPole-v1": cartpole_action,
    "Acrobot-v1": acrobot_action,
    "MountainCar-v0": mountaincar_action,
    "LunarLander-v3": lunar_lander_action,
}


def controller_for(env_id: str) -> Callable[[np.ndarray], int]:
    """Return the expert controller for a Gymnasium environment id.

    Args:
        env_id: Gymnasium environment id, e.g. ``"CartPole-v1"``.

    Returns:
        A deterministic function mapping an observation to a discrete action.

    Raises:
        UnknownEnvError: If no controller exists for ``env_id`` (a ``ValueError``).
        MissingDependencyError: The env needs a package that is not installed (LunarLander:
            Box2D); the message names the abco extra to install.
    """
    controller = CONTROLLERS.get(env_name(env_id))
    if controller is None:
        known = ", ".join(sorted(CONTROLLERS))
        raise UnknownEnvError(
            f"No classic-control expert for env id {env_id!r}; known ids: {known}"
        )
    check_env_dependencies(env_id)
    return controller


def rollout_returns(env_id: str, episodes: int = 100, seed: int = 0) -> np.ndarray:
    """Run the expert controller and collect undiscounted episode returns.

    Episode ``k`` is started with ``env.reset(seed=seed + k)`` and runs until termination or
    the environment's default time-limit truncation.

    Args:
        env_id: Gymnasium environment id with a registered controller.
        episodes: Number of episodes to run.
        seed: Seed of the first episode.

    Returns:
        Array of shape ``(episodes,)`` and dtype float64 with the per-episode returns.

    Raises:
        ValueError: If no controller exists for ``env_id``.
        MissingDependencyError: The env needs a package that is not installed.
    """
    policy = controller_for(env_id)
    returns = np.zeros(episodes, dtype=np.float64)
    env = gym.make(env_id)
    try:
        for k in range(episodes):
            obs, _ = env.reset(seed=seed + k)
            total = 0.0
            done = False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(policy(obs))
                total += float(reward)
                done = terminated or truncated
            returns[k] = total
    finally:
        env.close()
    return returns

"""LunarLander-v3's expert: Gymnasium's own training-free heuristic lander.

:func:`lunar_lander_action` is ``gymnasium.envs.box2d.lunar_lander.heuristic`` applied to the
observation: a PID-like rule that tilts the lander towards the pad, holds a hover height
proportional to its distance from the centre, and only brakes the fall once a leg touches.
The heuristic reads one thing from the env it is given, ``env.unwrapped.continuous``, to
choose between throttle values and the four discrete actions, so the expert hands it a
stand-in that answers ``False`` (LunarLander-v3's discrete actions) and works from the
observation alone, like the classic-control controllers.

Measured with :func:`abco_envs.experts.classic.rollout_returns` (``reset(seed=k)``,
Gymnasium 1.4.0, Box2D 2.3.10):

===========  =======  =======  ======  ==============
seeds        mean     min      max     return >= 200
===========  =======  =======  ======  ==============
0..19        263.88   180.04   319.98  18 of 20
0..99        252.83   -190.46  319.98  91 of 100
1000..1999   234.70   -294.51  319.92  893 of 1000
===========  =======  =======  ======  ==============

The env's "solved" line is a mean of 200; about one episode in ten ends below it, a few in a
crash.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from types import SimpleNamespace
from typing import Any

import numpy as np

from abco_envs.dependencies import check_env_dependencies

__all__ = ["lunar_lander_action"]

#: What the heuristic reads of its env: ``unwrapped.continuous`` (LunarLander-v3 is discrete).
_DISCRETE_LANDER = SimpleNamespace(unwrapped=SimpleNamespace(continuous=False))


@cache
def _heuristic() -> Callable[[Any, Any], Any]:
    """Gymnasium's heuristic, imported on first use (its module needs Box2D).

    Raises:
        MissingDependencyError: Box2D is not installed (the message names the extra).
    """
    check_env_dependencies("LunarLander-v3")
    from gymnasium.envs.box2d.lunar_lander import heuristic

    return heuristic


def lunar_lander_action(obs: np.ndarray) -> int:
    """Gymnasium's heuristic lander on one observation.

    Args:
        obs: Observation ``[x, y, vx, vy, angle, angular velocity, left leg, right leg]``.

    Returns:
        ``0`` (do nothing), ``1`` (left engine), ``2`` (main engine) or ``3`` (right engine).

    Raises:
        MissingDependencyError: Box2D is not installed (the message names the extra).

    Example:
        >>> import gymnasium as gym
        >>> env = gym.make("LunarLander-v3")
        >>> obs, _ = env.reset(seed=0)
        >>> lunar_lander_action(obs) in (0, 1, 2, 3)
        True
    """
    # The observation as the env returned it (float32): the heuristic's own arithmetic.
    return int(_heuristic()(_DISCRETE_LANDER, obs))

"""When an episode counts as a success (the paper's ``v_e``): one rule per environment.

==================  ===========================================  ============================
env                 success                                      known
==================  ===========================================  ============================
AbcoMaze*           the goal cell reached (the env terminates)   on the step it happens
CartPole-v1         195 steps survived                           on the 195th step
MountainCar-v0      the flag reached (the env terminates)        on the step it happens
Acrobot-v1          the tip above the line (the env terminates)  on the step it happens
LunarLander-v3      episode return >= 200                        at the end of the episode
==================  ===========================================  ============================

LunarLander terminates on a crash as on a landing, so its termination is no verdict; its
return is: 200 is the env's "solved" line (a landing earns +100 on top of the shaping, a crash
costs -100), and a return is only final once the episode has ended. The CartPole, MountainCar
and Acrobot rules are the ones the ABCO authors used.

An env whose ``info`` reports ``is_success`` (the Gymnasium-Robotics convention that
Stable-Baselines3 reads) is judged by that, wherever it reports it, before its rule. A run
may set the rule of any env for its process (:func:`set_success_rule`: ``abco train
--success``, and ``terminated`` for an env beyond the table).

Example:
    >>> SUCCESS_RULES["LunarLander-v3"]
    SuccessRule(kind='return', threshold=200.0)
    >>> is_success("LunarLander-v3", terminated=True, length=240, episode_return=-95.0)
    False
    >>> is_success("CartPole-v1", terminated=True, length=210, episode_return=210.0)
    True
    >>> is_success("Pendulum-v1", terminated=False, length=200, episode_return=-140.0,
    ...            info={"is_success": True})
    True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from abco_envs.errors import UnknownEnvError
from abco_envs.ids import MAZE_IDS, env_name

__all__ = ["RULE_KINDS", "SUCCESS_RULES", "SuccessRule", "is_success", "set_success_rule",
           "success_mask", "success_rule"]

#: ``terminated``: the env's termination is the goal; ``steps``: at least ``threshold`` steps
#: survived; ``return``: an episode return of at least ``threshold`` once the episode ended.
RULE_KINDS = ("terminated", "steps", "return")


@dataclass(frozen=True)
class SuccessRule:
    """How one environment's episodes are judged.

    Attributes:
        kind: One of :data:`RULE_KINDS`.
        threshold: The steps (``steps``) or the return (``return``) to reach; unused for
            ``terminated``.
    """

    kind: str
    threshold: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in RULE_KINDS:
            raise ValueError(f"unknown success rule kind {self.kind!r}; expected one of"
                             f" {', '.join(RULE_KINDS)}")

    def describe(self) -> str:
        """The rule in words.

        Example:
            >>> SuccessRule("steps", 195).describe()
            'survives 195 steps'
        """
        if self.kind == "steps":
            return f"survives {self.threshold:g} steps"
        if self.kind == "return":
            return f"episode return >= {self.threshold:g} at the end of the episode"
        return "the env terminates (its goal is reached)"


_TERMINATED = SuccessRule("terminated")
#: Env id (without module prefix) -> its :class:`SuccessRule`.
SUCCESS_RULES: Mapping[str, SuccessRule] = MappingProxyType({
    **{maze_id: _TERMINATED for maze_id in MAZE_IDS},
    "CartPole-v1": SuccessRule("steps", 195),
    "MountainCar-v0": _TERMINATED,
    "Acrobot-v1": _TERMINATED,
    "LunarLander-v3": SuccessRule("return", 200.0),
})


#: Rules a run set for this process (``abco train --success``, or ``terminated`` for an env
#: beyond the table): over the table's (:func:`set_success_rule`).
_RUN_RULES: dict[str, SuccessRule] = {}


def set_success_rule(env_id: str, rule: SuccessRule | None) -> None:
    """Judge ``env_id``'s episodes by ``rule`` in this process (``None``: by the table again).
    Where the env's ``info`` reports ``is_success``, that still decides."""
    if rule is None:
        _RUN_RULES.pop(env_name(env_id), None)
    else:
        _RUN_RULES[env_name(env_id)] = rule


def success_rule(env_id: str) -> SuccessRule:
    """The rule of ``env_id`` (with or without a module prefix): a run's
    (:func:`set_success_rule`), else the table's.

    Raises:
        UnknownEnvError: No rule for ``env_id`` (the message lists the envs with one).
    """
    rule = _RUN_RULES.get(env_name(env_id)) or SUCCESS_RULES.get(env_name(env_id))
    if rule is None:
        raise UnknownEnvError(f"no success rule for env {env_id!r} and its info reports no"
                              f" 'is_success'; envs with a rule: {', '.join(SUCCESS_RULES)}")
    return rule


def _reported(info: Mapping[str, Any] | None, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """``(is_success, where reported)`` of ``n`` episodes from an env's or a vector env's info
    (whose ``_is_success`` marks the slots that reported), or None when none reports it."""
    if not info or "is_success" not in info:
        return None
    values = np.broadcast_to(np.asarray(info["is_success"]).astype(bool), (n,))
    where = np.broadcast_to(np.asarray(info.get("_is_success", True), dtype=bool), (n,))
    return values, where


def success_mask(env_id: str, *, terminated: ArrayLike, lengths: ArrayLike, returns: ArrayLike,
                 ended: ArrayLike, info: Mapping[str, Any] | None = None) -> np.ndarray:
    """Which of a batch of episodes, after their latest step, count as a success.

    Call it after every step: a ``terminated`` or ``steps`` verdict is known on the step it
    happens, a ``return`` verdict only once the episode has ended (running episodes read
    ``False`` until then).

    Args:
        env_id: The env's id (with or without a module prefix).
        terminated: ``(B,)`` the env terminated the episode on this step.
        lengths: ``(B,)`` steps taken so far, this one included.
        returns: ``(B,)`` returns so far.
        ended: ``(B,)`` the episode is over (terminated, truncated or cut short).
        info: The env's (or vector env's, sliced to the batch) info of this step.

    Returns:
        ``(B,)`` bools.

    Raises:
        UnknownEnvError: ``env_id`` has no rule and ``info`` reports no ``is_success``.
    """
    terminated_arr = np.asarray(terminated, dtype=bool).reshape(-1)
    n = terminated_arr.size
    reported = _reported(info, n)
    if reported is not None and reported[1].all():
        return reported[0].copy()
    if reported is None or env_name(env_id) in SUCCESS_RULES or env_name(env_id) in _RUN_RULES:
        rule = success_rule(env_id)
        if rule.kind == "steps":
            verdict = np.asarray(lengths).reshape(-1) >= rule.threshold
        elif rule.kind == "return":
            over = np.asarray(returns, dtype=np.float64).reshape(-1) >= rule.threshold
            verdict = np.asarray(ended, dtype=bool).reshape(-1) & over
        else:
            verdict = terminated_arr.copy()
    else:  # no rule: only the slots that report is_success can succeed
        verdict = np.zeros(n, dtype=bool)
    if reported is not None:
        verdict = np.where(reported[1], reported[0], verdict)
    return np.asarray(verdict, dtype=bool)


def is_success(env_id: str, *, terminated: bool, length: int, episode_return: float,
               info: Mapping[str, Any] | None = None) -> bool:
    """Whether one finished episode counts as a success (see the module's table).

    Args:
        env_id: The env's id (with or without a module prefix).
        terminated: The env terminated the episode (rather than truncating it).
        length: Its number of steps.
        episode_return: The sum of its rewards.
        info: The info of its last step.

    Raises:
        UnknownEnvError: ``env_id`` has no rule and ``info`` reports no ``is_success``.
    """
    return bool(success_mask(env_id, terminated=[terminated], lengths=[length],
                             returns=[episode_return], ended=[True], info=info)[0])

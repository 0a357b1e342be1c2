"""The environments abco trains on beyond its own, read from their spaces; and ``--success``.

abco trains on its mazes, on the classic-control envs and LunarLander it ships datasets for
(:data:`abco_envs.CLASSIC_IDS`), and on any registered Gymnasium env, ``module:Id-v0``
included (Gymnasium imports ``module``, which registers ``Id-v0``), whose spaces it learns
from:

- observations: a ``Box`` vector (kind ``classic``: the vector networks, ``mlp``) or a
  ``uint8`` ``H x W x C`` image ``Box`` (kind ``image``: the compact CNN, ``cnn``, or
  ``resnet18``);
- actions: ``Discrete`` from 0.

Anything else is refused in one line naming what abco takes and a Gymnasium wrapper that
gives it; the user registers the wrapped env under an id of their own, in a module of their
own (``docs/training.md``, "Any Gymnasium env"). An env is made once per process to read its
spaces (:func:`env_spaces`).

An episode of such an env is a success where its ``info`` reports ``is_success``, else by the
run's ``--success`` rule (:func:`parse_success`): ``terminated`` (the default: the env ended
the episode itself, not by its step limit), ``return>=X`` (an episode return of at least
``X`` at its end) or ``steps>=N`` (at least ``N`` steps survived). The built-in envs keep
their own rules (:data:`abco_envs.SUCCESS_RULES`) unless ``--success`` is given.

Importing this module does not import torch.

Example:
    >>> parse_success("return>=0.5")
    SuccessRule(kind='return', threshold=0.5)
    >>> parse_success("steps >= 195").describe()
    'survives 195 steps'
    >>> parse_success("won")
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --success must be terminated, return>=X or steps>=N, got 'won'
"""  # noqa: E501

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from typing import Any

import abco_envs
from abco_envs.success import SuccessRule, set_success_rule
from abco_train.config.fields import ConfigError

__all__ = ["BUILTIN_ENVS", "EnvSpaces", "OBSERVATIONS_TAKEN", "env_spaces", "is_builtin_env",
           "parse_success", "run_success_rule", "use_success_rule"]  # fmt: skip

#: The envs abco ships datasets and experts for.
BUILTIN_ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)
#: What abco learns from, for messages.
OBSERVATIONS_TAKEN = "Box observations (a vector, or a uint8 HxWxC image) and Discrete actions"
_WHERE = "see 'Any Gymnasium env' in docs/training.md"
_SUCCESS = re.compile(r"(?P<kind>return|steps)>=(?P<value>[^\s]+)")


@dataclass(frozen=True)
class EnvSpaces:
    """What abco reads of an env's spaces.

    Attributes:
        kind: ``"classic"`` (vector observations) or ``"image"`` (``uint8`` images).
        observation_shape: The observations' shape.
        n_actions: The number of discrete actions.
    """

    kind: str
    observation_shape: tuple[int, ...]
    n_actions: int


def is_builtin_env(env_id: str) -> bool:
    """Whether ``env_id`` is one of the envs abco ships datasets (and experts) for."""
    return abco_envs.env_name(env_id) in BUILTIN_ENVS


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0][:300] if text else ''}"


def _space_text(space: Any) -> str:
    """A space in a few words (a ``Dict``'s keys, not its sub-spaces' long reprs)."""
    from gymnasium import spaces

    if isinstance(space, spaces.Dict):
        return f"Dict observations ({', '.join(map(str, space.spaces))})"
    return str(space)[:120]


def _observation_kind(space: Any, env_id: str) -> str:
    """``classic`` or ``image`` for the observation spaces abco learns from.

    Raises:
        ConfigError: Any other space (the message names a wrapper that gives one).
    """
    import numpy as np
    from gymnasium import spaces

    if isinstance(space, spaces.Box) and len(space.shape) == 1:
        return "classic"
    if isinstance(space, spaces.Box) and len(space.shape) == 3 and space.dtype == np.uint8:
        return "image"
    if isinstance(space, spaces.Dict):
        hint = ("minigrid.wrappers.ImgObsWrapper for MiniGrid's image, "
                "gymnasium.wrappers.FlattenObservation for a Dict of vectors")
    elif isinstance(space, spaces.Discrete):
        hint = "gymnasium.wrappers.FlattenObservation gives it as a one-hot vector"
    else:
        hint = "gymnasium.wrappers.FlattenObservation gives one vector"
    raise ConfigError(f"{env_id} has {_space_text(space)}; abco trains on {OBSERVATIONS_TAKEN}: "
                      f"register a wrapped env under an id of your own ({hint}; {_WHERE})")


@functools.lru_cache(maxsize=64)
def env_spaces(env_id: str) -> EnvSpaces:
    """The spaces of a registered Gymnasium env, made once (per process) to read them.

    Raises:
        ConfigError: ``env_id`` is no registered Gymnasium id (or its module does not
            import), the env cannot be made, or its spaces are none abco learns from
            (the message says which wrapper gives one).
    """
    import gymnasium as gym

    try:
        env = gym.make(env_id)
    except (gym.error.UnregisteredEnv, gym.error.DeprecatedEnv, ImportError) as err:
        raise ConfigError(
            f"unknown env id {env_id!r} ({_first_line(err)}); abco trains on "
            f"{', '.join(BUILTIN_ENVS)} and any registered Gymnasium env with "
            f"{OBSERVATIONS_TAKEN} (module:Id-v0 imports module first)") from None
    except Exception as err:  # the user's env constructor: any error, in one line
        raise ConfigError(f"cannot make env {env_id!r}: {_first_line(err)}") from None
    try:
        observations, actions = env.observation_space, env.action_space
    finally:
        env.close()
    if not isinstance(actions, gym.spaces.Discrete) or int(actions.start) != 0:
        raise ConfigError(f"{env_id} has actions {str(actions)[:120]}; abco trains on Discrete "
                          "actions from 0: register a wrapped env under an id of your own "
                          f"(gymnasium.wrappers.DiscretizeAction for a Box of actions; {_WHERE})")
    kind = _observation_kind(observations, env_id)
    return EnvSpaces(kind, tuple(observations.shape or ()), int(actions.n))


def parse_success(text: str) -> SuccessRule:
    """The rule ``--success`` names: ``terminated``, ``return>=X`` or ``steps>=N``.

    Raises:
        ConfigError: Any other text, a return that is not a finite number, or steps that are
            not a whole number of at least 1.
    """
    if not isinstance(text, str):
        raise ConfigError(f"--success must be text, got {text!r}")
    compact = re.sub(r"\s+", "", text)
    if compact == "terminated":
        return SuccessRule("terminated")
    match = _SUCCESS.fullmatch(compact)
    problem = "--success must be terminated, return>=X or steps>=N"
    if match is None:
        raise ConfigError(f"{problem}, got {text[:60]!r}")
    try:
        value = float(match["value"])
    except ValueError:
        raise ConfigError(f"{problem}, got {text[:60]!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"--success {match['kind']}>=X needs a finite number, got {text[:60]!r}")
    if match["kind"] == "steps" and (value < 1 or value != int(value)):
        raise ConfigError(f"--success steps>=N needs a whole N >= 1, got {text[:60]!r}")
    return SuccessRule(match["kind"], value)


def run_success_rule(env_id: str, success: str | None) -> SuccessRule | None:
    """The rule a run judges its episodes by where the env reports no ``is_success``:
    ``success`` if given, else the table's for a built-in env (``None``) and ``terminated``
    for any other."""
    if success is not None:
        return parse_success(success)
    return None if is_builtin_env(env_id) else SuccessRule("terminated")


def use_success_rule(env_id: str, success: str | None) -> None:
    """Make :func:`run_success_rule` the rule of ``env_id`` in this process (a run's
    evaluations and post-demonstrations read it through :mod:`abco_envs.success`)."""
    set_success_rule(env_id, run_success_rule(env_id, success))

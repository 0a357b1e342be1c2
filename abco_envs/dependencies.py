"""The optional packages some environments need, and the one-line refusal when they are missing.

LunarLander-v3 runs on Box2D, which abco installs through its ``box2d`` extra (the ``box2d``
wheel alone: Gymnasium's own ``gymnasium[box2d]`` extra would also install pygame, beside the
pygame-ce that abco's ``human`` extra installs, and both provide the ``pygame`` module).
:func:`check_env_dependencies` is called where abco first needs such an env (its expert, its
datasets, a training run), so a missing package ends in one line naming the extra to install
instead of Gymnasium's advice or a traceback.

Example:
    >>> check_env_dependencies("CartPole-v1")  # needs nothing beyond Gymnasium
    >>> EXTRAS["LunarLander-v3"]
    ('Box2D', 'box2d')
"""

from __future__ import annotations

import importlib

from abco_envs.errors import MissingDependencyError
from abco_envs.ids import env_name

__all__ = ["EXTRAS", "check_env_dependencies", "install_hint"]

#: Env id -> (module it imports, abco extra that installs that module).
EXTRAS: dict[str, tuple[str, str]] = {"LunarLander-v3": ("Box2D", "box2d")}


def install_hint(extra: str) -> str:
    """The command that installs an abco extra.

    Example:
        >>> install_hint("box2d")
        'pip install "abco[box2d]"'
    """
    return f'pip install "abco[{extra}]"'


def check_env_dependencies(env_id: str) -> None:
    """Return if every optional package ``env_id`` needs imports, else refuse in one line.

    Args:
        env_id: A Gymnasium id, with or without a module prefix.

    Raises:
        MissingDependencyError: A package the env needs does not import (a Gymnasium
            ``DependencyNotInstalled``); the message names the env and the extra to install.
        UnknownEnvError: ``env_id`` is not a string.
    """
    name = env_name(env_id)
    if name not in EXTRAS:
        return
    module, extra = EXTRAS[name]
    try:
        importlib.import_module(module)
    except ImportError:
        raise MissingDependencyError(
            f"{name} needs {module}, which is not installed: {install_hint(extra)}"
        ) from None

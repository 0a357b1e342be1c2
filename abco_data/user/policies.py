"""The policies :func:`abco_data.record` plays: a callable, a ``MODULE:CALLABLE``, or a
Stable-Baselines3 model.

A policy is called on **one** observation (as the env returns it, not a batch) and returns
one action: an integer of the ``Discrete`` action space (a Python or numpy integer, or an
integer array of one element, as SB3's ``predict`` gives). :func:`load_policy` turns the
command line's ``--policy`` into one:

- ``MODULE:CALLABLE``: ``MODULE`` is a ``.py`` file path or a dotted module name, imported as
  ``abco train --plugin`` imports plugins (a file as module ``abco_policy_<stem>``), and
  ``CALLABLE`` the name of the policy in it (``Class.attribute`` works too);
- ``PATH.zip``: a Stable-Baselines3 model, loaded with the algorithm class named by
  ``sb3_algo`` (``PPO``, ``DQN``, ...), or else the one the model's own policy class names
  (a DQN policy: ``DQN``; an actor-critic policy, PPO's or A2C's: ``PPO``, which predicts
  as the model saved). It plays ``model.predict(obs, deterministic=True)``.

Example:
    >>> from gymnasium import spaces
    >>> policy = checked_policy(lambda obs: 1, spaces.Discrete(2), "mine")
    >>> policy(None)
    1
    >>> checked_policy(lambda obs: 2.0, spaces.Discrete(2), "mine")(None)
    Traceback (most recent call last):
    abco_data.errors.InvalidParameterError: policy mine returned 2.0, not an action of Discrete(2)
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from abco_data.errors import DatasetError, InvalidParameterError
from abco_data.user.code import import_user_module, names_a_file

__all__ = ["Policy", "load_policy", "checked_policy", "policy_name", "SB3_MAX_DATA_BYTES"]

#: A policy on one observation.
Policy = Callable[[Any], Any]
#: The most bytes of a model zip's ``data`` member read to find its algorithm.
SB3_MAX_DATA_BYTES = 64 << 20


def policy_name(policy: object) -> str:
    """``module:qualname`` of a callable, for the file's creation parameters."""
    target = policy if hasattr(policy, "__qualname__") else type(policy)
    return f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', '?')}"


def checked_policy(policy: Policy, action_space: spaces.Discrete, what: str) -> Policy:
    """``policy`` whose every action is checked to be an integer of ``action_space``.

    Raises (when called):
        InvalidParameterError: An action that is not one (the message shows it).
    """
    n = int(action_space.n)

    def play(observation: Any) -> int:
        action = policy(observation)
        value = np.asarray(action)
        if value.size == 1 and value.dtype.kind in "iu":
            a = int(value.reshape(()))
            if 0 <= a < n:
                return a
        raise InvalidParameterError(f"policy {what} returned {action!r}, not an action of"
                                    f" Discrete({n})")

    return play


def _import_module(module: str, spec: str) -> Any:
    what = module if names_a_file(module) else f"module {module!r}"
    try:
        return import_user_module(module, "abco_policy")
    except FileNotFoundError:
        raise InvalidParameterError(f"policy {spec}: no file {module}") from None
    except Exception as exc:
        raise InvalidParameterError(f"policy {spec}: {what} failed to import:"
                                    f" {type(exc).__name__}: {exc}") from exc


def _callable(spec: str) -> Policy:
    module, sep, name = spec.rpartition(":")
    if not sep or not module or not name:
        raise InvalidParameterError(f"policy {spec!r}: expected MODULE:CALLABLE (a .py file"
                                    " or a dotted module name, then the policy's name) or"
                                    " the path of a Stable-Baselines3 model .zip")
    target: Any = _import_module(module, spec)
    for part in name.split("."):
        if not hasattr(target, part):
            raise InvalidParameterError(f"policy {spec}: {module} has no {name}")
        target = getattr(target, part)
    if not callable(target):
        raise InvalidParameterError(f"policy {spec}: {name} is not callable")
    return target


def _sb3_algorithm(path: Path) -> str:
    """The algorithm class the model's policy class names (see the module docstring)."""
    try:
        with zipfile.ZipFile(path) as archive:
            if archive.getinfo("data").file_size > SB3_MAX_DATA_BYTES:
                raise ValueError("its data member is too large")
            data = json.loads(archive.read("data"))
        module = data["policy_class"]["__module__"]
    except (OSError, KeyError, TypeError, ValueError, zipfile.BadZipFile) as err:
        raise InvalidParameterError(f"policy {path}: not a Stable-Baselines3 model .zip"
                                    f" ({type(err).__name__}: {err})") from err
    parts = str(module).split(".")
    if parts[:1] == ["stable_baselines3"] and len(parts) == 3 and parts[2] == "policies":
        return "PPO" if parts[1] == "common" else parts[1].upper()
    raise InvalidParameterError(f"policy {path}: its policy class comes from {module}; name"
                                " its algorithm (sb3_algo, --sb3-algo PPO)")


def _sb3_policy(path: Path, algo: str | None) -> Policy:
    try:
        import stable_baselines3 as sb3
    except ImportError as err:
        raise DatasetError("a Stable-Baselines3 model needs stable-baselines3: pip install"
                           " 'abco[rl]'") from err
    name = algo or _sb3_algorithm(path)
    classes = {n.upper(): getattr(sb3, n) for n in dir(sb3) if n.isupper()}
    if name.upper() not in classes:
        raise InvalidParameterError(f"unknown Stable-Baselines3 algorithm {name!r}; one of"
                                    f" {', '.join(sorted(classes))}")
    try:
        model = classes[name.upper()].load(path, device="cpu")
    except Exception as exc:  # SB3 and torch raise many kinds on a zip of another algorithm
        raise InvalidParameterError(f"policy {path}: cannot load it as a {name.upper()}"
                                    f" model ({type(exc).__name__}: {exc}); name its"
                                    " algorithm with --sb3-algo") from exc

    def predict(observation: Any) -> Any:
        return model.predict(observation, deterministic=True)[0]

    return predict


def load_policy(spec: str, *, sb3_algo: str | None = None) -> Policy:
    """The policy ``spec`` names (see the module docstring).

    Raises:
        InvalidParameterError: A missing file or module, a module that fails to import, a
            name it lacks, something not callable, a zip that is not an SB3 model.
        DatasetError: An SB3 model without stable-baselines3 installed.
    """
    if spec.endswith(".zip"):
        path = Path(spec)
        if not path.is_file():
            raise InvalidParameterError(f"policy {spec}: no such model file")
        return _sb3_policy(path, sb3_algo)
    if sb3_algo is not None:
        raise InvalidParameterError("sb3_algo (--sb3-algo) goes with a Stable-Baselines3"
                                    f" model .zip, not with policy {spec!r}")
    return _callable(spec)

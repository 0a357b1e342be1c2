"""The errors abco_envs raises for bad input, each naming what was wrong and the bad value.

They subclass the built-in errors that the same mistakes raised before (``ValueError`` and
``TypeError``; ``IndexError`` for an out-of-range option), so existing ``except`` clauses and
``pytest.raises`` checks keep working, while ``except abco_envs.errors.InvalidOptionError``
catches exactly the env's own refusals.

Example:
    >>> try:
    ...     raise OptionOutOfRangeError("reset option 'layout_index' 100 is out of range")
    ... except IndexError as error:  # what an out-of-range layout_index raised before
    ...     isinstance(error, (InvalidOptionError, ValueError))
    True
"""

from __future__ import annotations

from gymnasium.error import DependencyNotInstalled

__all__ = [
    "InvalidActionError",
    "InvalidLayoutError",
    "InvalidOptionError",
    "MissingDependencyError",
    "OptionOutOfRangeError",
    "UnknownEnvError",
]


class InvalidOptionError(ValueError, TypeError):
    """A constructor argument or reset option of a maze env of the wrong type or value."""


class OptionOutOfRangeError(InvalidOptionError, IndexError):
    """An integer option outside its range (``layout_index`` past the split, ``start`` outside
    the maze)."""


class InvalidActionError(ValueError, TypeError):
    """An action that is not an integer, or not one of the env's actions."""


class InvalidLayoutError(ValueError):
    """A layout array that is not a consistent, connected maze in gym-maze's encoding."""


class UnknownEnvError(ValueError):
    """An env id that abco has no environment or expert for (or that is not a string)."""


class MissingDependencyError(DependencyNotInstalled):
    """An env whose optional dependency is not installed; the message names the abco extra
    that installs it (a Gymnasium ``DependencyNotInstalled``, as Gymnasium's own)."""

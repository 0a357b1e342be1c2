"""The random policy that pre-demonstrations (``I_pre``) are made of."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["RandomPolicy", "hold_range"]


def hold_range(hold: Any) -> tuple[int, int]:
    """``(lo, hi)`` of a ``RandomPolicy`` hold: ``k`` is ``(k, k)``, a pair stays itself.

    Example:
        >>> hold_range(4), hold_range([1, 8])
        ((4, 4), (1, 8))

    Raises:
        ValueError: Not a step count >= 1 or a pair of them with ``lo <= hi``.
    """
    def count(x: Any) -> bool:
        return isinstance(x, (int, np.integer)) and not isinstance(x, bool) and bool(x >= 1)

    pair = (hold, hold) if count(hold) else tuple(hold) if isinstance(hold, (list, tuple)) \
        else ()
    if len(pair) != 2 or not all(map(count, pair)) or pair[0] > pair[1]:
        raise ValueError(f"hold must be a step count >= 1 or a pair [lo, hi] of them with"
                         f" lo <= hi, got {hold!r}")
    return int(pair[0]), int(pair[1])


class RandomPolicy:
    """Uniform random actions from a discrete space, drawn from its own seeded generator.

    With ``hold`` each drawn action is repeated: for ``hold`` steps (an int), or for a number
    of steps drawn uniformly from ``lo..hi`` (a pair, inclusive) after each action, from the
    same generator. Held actions pump energy into a pendulum the way a controller does, so a
    dataset of them covers states that one-step random actions rarely reach. ``hold=1`` (the
    default) draws exactly the actions it always drew.

    Example:
        >>> from gymnasium import spaces
        >>> first = [RandomPolicy(spaces.Discrete(4), seed=0)(None, {}) for _ in range(3)]
        >>> again = [RandomPolicy(spaces.Discrete(4), seed=0)(None, {}) for _ in range(3)]
        >>> first == again and all(0 <= a < 4 for a in first)
        True
        >>> held = RandomPolicy(spaces.Discrete(3), seed=0, hold=4)
        >>> actions = [held(None, {}) for _ in range(8)]
        >>> actions[:4] == [actions[0]] * 4 and actions[4:] == [actions[4]] * 4
        True

    Raises:
        TypeError: Not a ``Discrete`` action space.
        ValueError: A bad ``hold`` (see :func:`hold_range`).
    """

    def __init__(self, action_space: spaces.Space[Any], seed: int | None = None,
                 hold: int | tuple[int, int] | list[int] = 1) -> None:
        if not isinstance(action_space, spaces.Discrete):
            raise TypeError(f"RandomPolicy needs a Discrete action space, got {action_space}")
        self.hold = hold_range(hold)
        self.n, self.start = int(action_space.n), int(action_space.start)
        self.rng = np.random.default_rng(seed)
        self._action, self._left = self.start, 0

    def __call__(self, obs: Any, info: dict[str, Any]) -> int:
        """The held action, or a new uniform one when its hold is over; ``obs`` is ignored."""
        if self._left == 0:
            self._action = self.start + int(self.rng.integers(self.n))
            lo, hi = self.hold
            self._left = lo if lo == hi else int(self.rng.integers(lo, hi + 1))
        self._left -= 1
        return self._action

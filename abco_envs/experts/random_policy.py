"""The random policy that pre-demonstrations (``I_pre``) are made of."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["RandomPolicy"]


class RandomPolicy:
    """Uniform random actions from a discrete space, drawn from its own seeded generator.

    Example:
        >>> from gymnasium import spaces
        >>> first = [RandomPolicy(spaces.Discrete(4), seed=0)(None, {}) for _ in range(3)]
        >>> again = [RandomPolicy(spaces.Discrete(4), seed=0)(None, {}) for _ in range(3)]
        >>> first == again and all(0 <= a < 4 for a in first)
        True
    """

    def __init__(self, action_space: spaces.Space[Any], seed: int | None = None) -> None:
        if not isinstance(action_space, spaces.Discrete):
            raise TypeError(f"RandomPolicy needs a Discrete action space, got {action_space}")
        self.n, self.start = int(action_space.n), int(action_space.start)
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs: Any, info: dict[str, Any]) -> int:
        """One uniform action; the observation is ignored."""
        return self.start + int(self.rng.integers(self.n))

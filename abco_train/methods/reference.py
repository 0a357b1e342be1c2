"""The two reference policies of every benchmark report: ``random`` and ``expert``.

The normalised score puts a uniform random policy at 0 and the expert at 1. These two methods
run *through the same evaluation path* as every trained method (the harness, its seeds, its
protocols, its layouts), with no training and no environment interaction counted, so their
rows in a report test the score's references rather than restate them: ``random`` should score
about 0 and ``expert`` about 1 on every task.

* ``random``: uniform random actions, drawn from the run's seeded generator.
* ``expert``: the expert the datasets were recorded with
  (:func:`abco_envs.experts.expert_policy`): mazes, the shortest-path expert of the layout
  played (it reads the agent's cell and the layout's id from the env's ``info``, as the
  dataset generator does); other envs, their controller on the observation. A dataset of the
  user's own (:func:`abco_data.record`) names the policy that recorded it (its creation
  parameters' ``policy``, a ``MODULE:CALLABLE`` or a model ``.zip``): that policy, reloaded
  by :func:`abco_data.user.policies.load_policy`, one observation at a time. An env without an
  expert of abco's whose dataset names no policy it can reload (an imported Minari dataset)
  has no ``expert`` row: the method refuses in one line.

Example:
    >>> from abco_train.methods.registry import get_method
    >>> get_method("random").__name__, get_method("expert").__name__
    ('RandomReference', 'ExpertReference')
"""

from __future__ import annotations

from typing import Any

import numpy as np

from abco_train.methods.base import Method
from abco_train.methods.registry import register

__all__ = ["RandomReference", "ExpertReference", "REFERENCE_METHODS"]

#: The reference methods' names (a report's ``random`` and ``expert`` rows).
REFERENCE_METHODS = ("random", "expert")


class _Reference(Method):
    """A policy that needs no training: no iterations, nothing to checkpoint."""

    @property
    def num_iterations(self) -> int:
        return 0

    def train_iteration(self, iteration: int) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state:
            raise ValueError("a reference method's checkpoint holds nothing")


@register("random")
class RandomReference(_Reference):
    """Uniform random actions (the score's 0)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.rng.integers(self.data.n_actions, size=len(obs))


@register("expert")
class ExpertReference(_Reference):
    """The datasets' expert (the score's 1)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        from abco_envs.experts import expert_policy

        recorded = _recorded_policy(self.config)
        self._policy = (recorded if recorded is not None
                        else expert_policy(self.config.env, seed=self.config.seed))
        self._layouts: dict[str, np.ndarray] = {}
        if self.data.is_maze:
            self._layouts = _known_layouts(self.config, self.data.train_layouts)

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        if not self.data.is_maze:
            return np.array([self._policy(o, {}) for o in obs], dtype=np.int64)
        if info is None or "position" not in info or "layout_id" not in info:
            raise ValueError("the maze expert needs the env's info (position and layout_id)")
        actions = np.empty(len(obs), dtype=np.int64)
        for i, (position, layout_id) in enumerate(zip(info["position"], info["layout_id"])):
            self._policy.use_layout(self._layouts[str(layout_id)])  # type: ignore[attr-defined]
            actions[i] = self._policy(obs[i], {"position": position})
        return actions

    act.reads_info = True  # type: ignore[attr-defined]  # rollout() passes the env's info


def _recorded_policy(cfg: Any) -> Any:
    """The policy that recorded the run's expert dataset, as ``(obs, info) -> action``, when
    the dataset is the user's own (:func:`abco_data.record`); ``None`` for abco's datasets.

    Raises:
        ConfigError: An env without an expert of abco's whose dataset names no policy, or
            one that cannot be reloaded (the message says which and why).
    """
    import json

    from gymnasium import spaces

    from abco_data.errors import DatasetError
    from abco_data.user.policies import checked_policy, load_policy
    from abco_data.user.record import GENERATOR
    from abco_train.config.envs import is_builtin_env
    from abco_train.config.fields import ConfigError
    from abco_train.harness.training_data import KINDS, resolve_dataset

    dataset = resolve_dataset(cfg.expert_data, cfg.env, KINDS["expert"], cache_dir=cfg.cache_dir)
    try:
        recorder = dataset.attrs.get("generator")
        params = json.loads(str(dataset.attrs.get("creation_params", "{}")))
        name = str(dataset.id or dataset.path)
        n_actions = int(dataset.action_space.n)
    finally:
        dataset.close()
    spec = params.get("policy") if isinstance(params, dict) else None
    if recorder != GENERATOR or not isinstance(spec, str):
        if is_builtin_env(cfg.env):
            return None
        raise ConfigError(f"--method expert: {cfg.env} has no expert of abco's and its expert "
                          f"dataset {name} names no policy that recorded it (an imported "
                          "dataset); its score references still stand")  # fmt: skip
    try:
        policy = checked_policy(load_policy(spec), spaces.Discrete(n_actions), spec)
    except DatasetError as err:
        raise ConfigError(f"--method expert: cannot reload the policy that recorded {name}: "
                          f"{err}") from None  # fmt: skip
    return lambda obs, info: policy(obs)


def _known_layouts(cfg: Any, train_layouts: np.ndarray | None) -> dict[str, np.ndarray]:
    """Every layout a final evaluation may play, by structural id: the pool's splits, the
    run's training layouts, the fresh evaluation layouts."""
    import abco_envs
    from abco_envs.maze.layout import layout_hash
    from abco_train.config.run import fresh_evaluation
    from abco_train.harness.evaluation import FRESH_LAYOUTS, FRESH_SEED

    n = abco_envs.maze_size(cfg.env)
    pool = abco_envs.layout_pool(n)
    stacks = [np.asarray(pool.split("train")), np.asarray(pool.split("test"))]
    if train_layouts is not None:
        stacks.append(np.asarray(train_layouts))
    if fresh_evaluation(cfg):
        stacks.append(abco_envs.fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED))
    return {layout_hash(c): c for stack in stacks for c in stack}

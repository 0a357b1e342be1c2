"""A user's own IfO method for abco: nearest-neighbour BCO ("knn-ifo").

Inverse dynamics by nearest neighbour: each expert pair ``(s, s')`` gets the action of the
pre-demonstration transition closest to it in ``(s, s' - s)`` (standardised); the policy
then acts like the expert state nearest to its observation. No training, numpy only, for
the vector environments (CartPole-v1, Acrobot-v1, MountainCar-v0). It counts the
pre-demonstration transitions it uses (``self.count``); it takes no environment steps of its
own, so its other interaction counts stay 0. Its one option is typed (:class:`KnnOptions`):
``--knn-max-pre 2000`` on the command line, or ``--method-options '{"max_pre": 2000}'``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from abco_train.config import RunConfig
from abco_train.config.fields import MethodOptions, option
from abco_train.harness.training_data import TrainingData
from abco_train.methods import Method, register


def _nearest(queries: np.ndarray, points: np.ndarray, chunk: int = 1024) -> np.ndarray:
    """Index of the nearest row of ``points`` for every row of ``queries`` (Euclidean)."""
    out = np.empty(len(queries), dtype=np.int64)
    sq = (points**2).sum(1)
    for start in range(0, len(queries), chunk):
        q = queries[start : start + chunk]
        out[start : start + chunk] = np.argmin(sq[None, :] - 2.0 * q @ points.T, axis=1)
    return out


@dataclass
class KnnOptions(MethodOptions):
    """The method's options: checked, shown in ``abco train --method knn-ifo --help``."""

    flag_prefix = "knn-"
    max_pre: int = option("pre-demonstration transitions used", 5000, min=1)


@register("knn-ifo")
class NearestNeighbourIfO(Method):
    """BCO(0) with nearest-neighbour IDM and policy."""

    Options = KnnOptions
    options: KnnOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)  # sets self.options from config.method_options
        keep = rng.permutation(len(data.pre_t))[: self.options.max_pre]  # the seed picks them
        self.count("pre_demonstration", len(keep))  # the run's cost: pre-demonstrations used
        rows = data.pre_t[keep]
        s = data.pre_obs[rows].astype(np.float64)
        self.pre_x = np.concatenate([s, data.pre_obs[rows + 1] - s], axis=1)
        self.pre_a = data.pre_actions[keep]
        self.mean, self.std = self.pre_x.mean(0), self.pre_x.std(0) + 1e-8
        self.states = data.expert_obs[data.expert_t].astype(np.float64)
        self.labels = np.zeros(len(self.states), dtype=np.int64)

    @property
    def num_iterations(self) -> int:
        """One pass: nothing is learnt from the post-demonstrations."""
        return 1

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Label every expert pair with its nearest pre-demonstration's action."""
        d = self.data
        nxt = d.expert_obs[d.expert_t + 1].astype(np.float64)
        x = np.concatenate([self.states, nxt - self.states], axis=1)
        idx = _nearest((x - self.mean) / self.std, (self.pre_x - self.mean) / self.std)
        self.labels = self.pre_a[idx].astype(np.int64)
        accuracy = float((self.labels == d.expert_eval_actions).mean())
        return {"idm_expert_accuracy": accuracy}

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The label of the nearest expert state."""
        s = (np.asarray(obs, dtype=np.float64) - self.mean[: obs.shape[1]]) / self.std[
            : obs.shape[1]
        ]
        points = (self.states - self.mean[: obs.shape[1]]) / self.std[: obs.shape[1]]
        return self.labels[_nearest(s, points)]

    def expert_labels(self) -> np.ndarray | None:
        """The inferred expert actions (plotted by the harness and ``abco report``)."""
        return self.labels

    def state_dict(self) -> dict[str, Any]:
        """All that a resumed run needs, as data (a numpy array here; no other objects)."""
        return {"labels": self.labels}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.labels = state["labels"]

"""The run config's defaults, as tables you can read.

A ``None`` field of :class:`abco_train.config.run.RunConfig` takes, in this order, the
default of the run's env kind and preset (:data:`DEFAULTS`), its environment's
(:data:`ENV_DEFAULTS`), its regime's (:data:`REGIME_DEFAULTS`), with ``layouts`` the
procedural datasets (:data:`LAYOUT_DEFAULTS`), then the method's own
(:meth:`abco_train.methods.base.Method.defaults`); fields set by the user always win. A
callable default is called with the env id. A method's own options have tables of their own
(e.g. :mod:`abco_train.methods.bco.options`).
"""

from __future__ import annotations

from typing import Any

__all__ = ["DEFAULTS", "ENV_DEFAULTS", "REGIME_DEFAULTS", "LAYOUT_DEFAULTS",
           "procedural_dataset", "start_cell_dataset"]  # fmt: skip


def start_cell_dataset(env_id: str) -> str:
    """The maze's pre-demonstrations from the start cell without wall hits (authors regime)."""
    from abco_data.registry import start_cell_dataset_id  # abco_data only when asked

    return start_cell_dataset_id(env_id)


def procedural_dataset(kind: str) -> Any:
    """A callable default: the env's procedural ``kind`` (``expert`` or ``pre``) dataset id."""

    def dataset(env_id: str) -> str:
        from abco_data.registry import procedural_dataset_id

        return procedural_dataset_id(env_id, kind)

    return dataset


#: Defaults of the ``None`` fields by (env kind, preset). Mazes train on 64x64 RGB frames,
#: classic control (and any other env of vector observations) on state vectors, other image
#: envs (``image``: any size, e.g. MiniGrid's 7x7x3 symbolic view) on their frames with the
#: mazes' settings; ``paper`` is the paper's ResNet-18 and its optimiser; ``general`` (unseen
#: layouts) reads the maze cell by cell and plans over the cells (``cellplan``: no weight
#: tied to a position).
DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("maze", "cpu"): {"iterations": 2, "arch": "cnn", "attention": True, "batch_size": 64,
                      "lr": 1e-3},
    ("maze", "paper"): {"iterations": 2, "arch": "resnet18", "attention": True,
                        "batch_size": 32, "lr": 1e-4},
    ("maze", "general"): {"iterations": 2, "arch": "cellplan", "attention": True,
                          "batch_size": 64, "lr": 1e-3},
    ("classic", "cpu"): {"iterations": 2, "arch": "mlp", "attention": True, "batch_size": 512,
                         "lr": 3e-3, "eval_episodes": 100},
    ("classic", "paper"): {"iterations": 2, "arch": "mlp", "attention": True, "batch_size": 32,
                           "lr": 1e-3, "eval_episodes": 100},
    ("image", "cpu"): {"iterations": 2, "arch": "cnn", "attention": True, "batch_size": 64,
                       "lr": 1e-3, "eval_episodes": 100},
    ("image", "paper"): {"iterations": 2, "arch": "resnet18", "attention": True,
                         "batch_size": 32, "lr": 1e-4, "eval_episodes": 100},
}  # fmt: skip

#: Per-environment changes on top of :data:`DEFAULTS` (any preset).
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    # Every Acrobot rollout reaches the goal, so after iteration 0 the IDM learns from I_pos
    # alone and its accuracy on the expert's (fast, off-I_pre) states rises each iteration
    # (0.84 -> 0.97 -> 0.99); the policy follows, and its training-time AER stops improving
    # only at about iteration 15-30 (alpha 10: -79.95, alpha 30: -77.67 on the validation
    # seeds 100-102; every seed better). Iterations cost seconds.
    "Acrobot-v1": {"iterations": 30},
}

#: The datasets of a run with ``--layouts`` (unless ``--expert-data`` / ``--pre-data`` are
#: given): the procedural datasets of its maze, whose first K layouts it trains on.
LAYOUT_DEFAULTS: dict[str, Any] = {"expert_data": procedural_dataset("expert"),
                                   "pre_data": procedural_dataset("pre")}

#: The authors' data and schedule (their public code, where the paper is silent): more
#: iterations; for mazes, pre-demonstrations recorded as an agent that resets the env would:
#: from the start cell, moves into walls dropped (``{maze}-pre-start-v0``). Their one IDM and
#: one policy epoch per iteration are the BCO family's (:mod:`abco_train.methods.bco.options`).
REGIME_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("maze", "authors"): {"iterations": 10, "pre_data": start_cell_dataset},
    ("classic", "authors"): {"iterations": 10},
    ("image", "authors"): {"iterations": 10},
}

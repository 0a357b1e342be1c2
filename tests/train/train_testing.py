"""Tiny datasets and configs for fast trainer tests (shared by tests/train/)."""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import abco_data
import abco_envs
from abco_train.config.run import RunConfig
from abco_train.methods.registry import config_from_record, options_class

TINY = {
    "maze_expert": {"layouts": 2, "solutions_per_layout": 1, "reference_episodes": 2},
    "maze_pre": {"layouts": 2, "episodes_per_layout": 4, "max_steps": 5,
                 "reference_episodes": 2},
    "classic_expert": {"episodes": 1, "reference_episodes": 2, "reference_expert_episodes": 1},
    "classic_pre": {"transitions": 300, "reference_episodes": 2, "reference_expert_episodes": 1},
}


def tiny_data_factory(root):
    """``env -> (expert file, pre file)``, each generated once into ``root`` by abco_data."""
    cache: dict[str, tuple[str, str]] = {}

    def get(env_id: str) -> tuple[str, str]:
        if env_id not in cache:
            family = "maze" if env_id in abco_envs.MAZE_IDS else "classic"
            paths = []
            for kind, key in (("expert", "expert"), ("pre_demonstrations", "pre")):
                ds_id = abco_data.dataset_id(env_id, kind)
                path = root / f"{ds_id.split('/')[1]}.hdf5"
                abco_data.generate(ds_id, path, progress=False, **TINY[f"{family}_{key}"])
                paths.append(str(path))
            cache[env_id] = (paths[0], paths[1])
        return cache[env_id]

    return get


def tiny_config(env_id, method, data, run_dir, **changes) -> RunConfig:
    expert, pre = data(env_id)
    values = dict(
        env=env_id, method=method, seed=0, iterations=1, idm_epochs=1, policy_epochs=1,
        first_epochs_factor=1, eval_layouts=2, eval_episodes=2, expert_data=expert,
        pre_data=pre, run_dir=str(run_dir), quiet=True, plot_layouts=2, eval_max_steps=30,
        plots=False,
    )
    values.update(changes)
    options = options_class(method)
    if "schedule" in options.names():  # tiny counts, not a converged schedule
        fixed = next(f.metadata["choices"][0] for f in fields(options) if f.name == "schedule")
        values["method_options"] = {"schedule": fixed, **(values.get("method_options") or {})}
    return config_from_record(values)  # BCO options may be given as keywords


def one_error_line(err: str, *needles: str) -> None:
    """``err`` is one ``error:`` line holding every needle."""
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, err


def train_argv(cfg: Any, **changes: Any) -> list[str]:
    """``abco train`` of ``cfg`` (a tiny config) with ``changes`` to its options."""
    values = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed, "run-dir": cfg.run_dir,
              "expert-data": cfg.expert_data, "pre-data": cfg.pre_data, "iterations": 1,
              "idm-epochs": 1, "policy-epochs": 1, "first-epochs-factor": 1, "eval-layouts": 2,
              "eval-episodes": 2, "plot-layouts": 2, "eval-max-steps": 30, "schedule": "epochs",
              **changes}
    return ["train", "--quiet", "--no-plots",
            *[x for k, v in values.items() for x in (f"--{k}", str(v))]]


#: GAIfO's tiny PPO: rounds of n_steps * n_envs = 32 env steps; 96 steps at most without a
#: budget.
GAIFO_TINY = {"rl_steps": 96, "n_envs": 2, "n_steps": 16, "batch_size": 16, "n_epochs": 1,
              "d_batch_size": 16, "features_dim": 32, "net_arch": [16]}  # fmt: skip


def gaifo_config(env_id, data, run_dir, **changes) -> RunConfig:
    """A tiny GAIfO run's config (:data:`GAIFO_TINY`, ``changes``' method_options over it)."""
    options = {**GAIFO_TINY, **changes.pop("method_options", {})}
    return tiny_config(env_id, "gaifo", data, run_dir, device="cpu", method_options=options,
                       **changes)  # fmt: skip

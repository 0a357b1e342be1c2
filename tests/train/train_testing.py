"""Tiny datasets and configs for fast trainer tests (shared by tests/train/)."""

from __future__ import annotations

import abco_data
import abco_envs
from abco_train.config.run import RunConfig
from abco_train.methods.registry import config_from_record

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
    return config_from_record(values)  # BCO options may be given as keywords

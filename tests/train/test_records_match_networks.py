"""A run's record tells the truth about its networks: ``attention`` in ``config.json`` is
true exactly where the method built self-attention layers."""

from __future__ import annotations

import pytest
import torch
from train_testing import GAIFO_TINY, tiny_config

from abco_train.config.run import RunConfig
from abco_train.harness.runtime import seed_everything
from abco_train.harness.training_data import load_training_data
from abco_train.methods.registry import available, get_method, resolve_config
from abco_train.networks.encoders import FeatureSelfAttention
from abco_train.networks.layers import SelfAttention2d

#: Methods that train networks (the references train none).
LEARNERS = [m for m in available() if m not in ("random", "expert")]


def _has_attention(method) -> bool:
    networks = [v for v in vars(method).values() if isinstance(v, torch.nn.Module)]
    assert networks, f"{type(method).__name__} keeps no network as an attribute"
    return any(isinstance(layer, (FeatureSelfAttention, SelfAttention2d))
               for net in networks for layer in net.modules())  # fmt: skip


@pytest.mark.parametrize("env", ["CartPole-v1", "AbcoMaze3x3-v0"])
@pytest.mark.parametrize("name", LEARNERS)
def test_the_recorded_attention_is_the_networks(tiny_data, tmp_path, name, env):
    extra = {"method_options": GAIFO_TINY} if name == "gaifo" else {}
    cfg = resolve_config(tiny_config(env, name, tiny_data, tmp_path, device="cpu", **extra))
    method = get_method(name)(cfg, load_training_data(cfg), seed_everything(cfg.seed))
    assert _has_attention(method) is cfg.attention


def test_ilpo_runs_without_attention_whatever_its_record_says(tmp_path) -> None:
    """ILPO's networks read no ``attention``: ``--attention`` resolves to its run as it is,
    and a record of an older version (which said ``true``) is the same run."""
    from dataclasses import asdict

    from abco_train.methods.registry import identity

    given = RunConfig(env="CartPole-v1", method="ilpo", run_dir=str(tmp_path), attention=True)
    assert resolve_config(given).attention is False
    old = {**asdict(given), "attention": True}
    assert identity(old) == identity(asdict(RunConfig(env="CartPole-v1", method="ilpo",
                                                      run_dir=str(tmp_path))))  # fmt: skip

"""Unit tests of abco_train: attention, networks, sampling and metrics."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from gymnasium import spaces

from abco_train.harness.metrics import performance, summarize
from abco_train.methods.bco.sampling import (
    draw_by_class,
    largest_remainder,
    run_action_distribution,
    sample_training_set,
)
from abco_train.networks import layers
from abco_train.networks.builders import build_networks
from abco_train.networks.encoders import FeatureSelfAttention
from abco_train.networks.layers import SelfAttention2d

# -- attention ---------------------------------------------------------------------------------


@pytest.mark.parametrize("module", [SelfAttention2d(16, 8), FeatureSelfAttention(12)])
def test_attention_is_identity_at_init_and_acts_once_mu_is_set(module):
    torch.manual_seed(0)
    x = torch.randn(5, 16, 4, 3) if isinstance(module, SelfAttention2d) else torch.randn(5, 12)
    assert torch.equal(module(x), x)
    with torch.no_grad():
        module.mu.fill_(0.5)
    y = module(x)
    assert y.shape == x.shape
    assert not torch.allclose(y, x)


def test_attention_mixes_positions():
    """The output at one position depends on the features at the others (softmax over N)."""
    torch.manual_seed(0)
    sa = SelfAttention2d(8, 2)
    with torch.no_grad():
        sa.mu.fill_(1.0)
    x = torch.randn(1, 8, 3, 3)
    x2 = x.clone()
    x2[0, :, 2, 2] += 5.0
    assert not torch.allclose(sa(x)[0, :, 0, 0], sa(x2)[0, :, 0, 0])


@pytest.mark.parametrize("side", [(3, 4), (1, 12), (4, 4), (5, 5)])
def test_attention_is_the_papers_softmax_on_either_path(side, monkeypatch):
    """Short maps take their softmax over a leading dim (a CPU speed path); both paths give
    ``beta_{j,i} = softmax_i(f(x_i) . g(x_j))``, checked against the formula written out."""
    torch.manual_seed(0)
    sa = SelfAttention2d(8, 2)
    x = torch.randn(3, 8, *side)
    tokens = x.flatten(2).transpose(1, 2)
    key, query, value = sa.key(tokens), sa.query(tokens), sa.value(tokens)
    beta = torch.exp(query @ key.transpose(1, 2))
    beta = beta / beta.sum(-1, keepdim=True)
    expected = sa.out(beta @ value).transpose(1, 2).reshape(x.shape)
    grads = []
    for threshold in (0, 10_000):  # every map on the long path, then on the short one
        monkeypatch.setattr(layers, "SHORT_SOFTMAX", threshold)
        torch.testing.assert_close(sa.attend(x), expected, rtol=1e-5, atol=1e-6)
        sa.zero_grad()
        sa.attend(x).square().sum().backward()
        grads.append([p.grad.clone() for p in (sa.key.weight, sa.query.weight, sa.value.weight)])
    for long_path, short_path in zip(*grads):  # the backward passes agree too
        torch.testing.assert_close(short_path, long_path, rtol=1e-4, atol=1e-5)


def test_feature_attention_is_not_a_single_token():
    """Each feature is a token: the attention weights span all D features."""
    torch.manual_seed(0)
    fsa = FeatureSelfAttention(6)
    with torch.no_grad():
        fsa.mu.fill_(1.0)
    x = torch.randn(2, 6)
    x2 = x.clone()
    x2[:, 5] += 3.0
    # changing feature 5 changes feature 0's output through the attention, not just feature 5
    assert not torch.allclose(fsa(x)[:, 0], fsa(x2)[:, 0])


def test_attention_params_get_gradients():
    fsa = FeatureSelfAttention(4)
    fsa(torch.randn(3, 4)).sum().backward()
    assert fsa.mu.grad is not None and fsa.mu.grad.abs() > 0


@pytest.mark.parametrize("arch", ["cnn", "resnet18"])
@pytest.mark.parametrize("attention", [True, False])
def test_image_networks_shapes(arch, attention):
    space = spaces.Box(0, 255, (64, 64, 3), dtype=np.uint8)
    policy, idm = build_networks(space, 4, arch=arch, attention=attention)
    obs = torch.randint(0, 255, (2, 64, 64, 3), dtype=torch.uint8)
    policy.eval(), idm.eval()
    assert policy(obs).shape == (2, 4)
    assert idm(obs, obs).shape == (2, 4)
    n_sa = sum(isinstance(m, SelfAttention2d) for m in policy.modules())
    assert n_sa == (2 if attention else 0)


def test_vector_networks_follow_the_paper():
    policy, idm = build_networks(spaces.Box(-1, 1, (6,)), 3, arch="mlp", attention=True)
    linears = [m for m in policy.modules() if isinstance(m, torch.nn.Linear)
               and m.out_features in (12, 3) and m.in_features in (6, 12)]
    assert [(m.in_features, m.out_features) for m in linears] == [
        (6, 12), (12, 12), (12, 12), (12, 12), (12, 3)]
    assert sum(isinstance(m, FeatureSelfAttention) for m in policy.modules()) == 2
    assert idm.encoder.body[0].in_features == 12  # (s_t, s_t+1) concatenated
    assert idm(torch.zeros(4, 6), torch.zeros(4, 6)).shape == (4, 3)


# -- sampling ----------------------------------------------------------------------------------


def _pos(n_runs=10, steps=20, seed=0):
    rng = np.random.default_rng(seed)
    run_ids = np.repeat(np.arange(n_runs), steps)
    actions = rng.integers(0, 4, size=n_runs * steps)
    return actions, run_ids


def test_largest_remainder_sums_exactly():
    rng = np.random.default_rng(1)
    for _ in range(50):
        shares = rng.random(5)
        total = int(rng.integers(0, 1000))
        sizes = largest_remainder(total, shares)
        assert sizes.sum() == total
        assert np.all(np.abs(sizes - total * shares / shares.sum()) < 1.0 + 1e-9)


@pytest.mark.parametrize("wins_count", [0, 1, 3, 7, 10])
def test_sizes_follow_the_win_rate(wins_count):
    actions, run_ids = _pos()
    wins = np.zeros(10, dtype=bool)
    wins[:wins_count] = True
    pre = np.repeat(np.arange(4), 250)
    s = sample_training_set(pre, actions, run_ids, wins, size=400,
                            rng=np.random.default_rng(0))
    w = wins_count / 10
    assert s.win_rate == pytest.approx(w)
    assert len(s.pos_indices) == round(400 * w)
    assert len(s.pre_indices) == 400 - round(400 * w)


def test_partial_draws_only_from_winning_runs_and_whole_from_all():
    actions, run_ids = _pos()
    wins = np.array([True, False] * 5)
    pre = np.repeat(np.arange(4), 100)
    s = sample_training_set(pre, actions, run_ids, wins, 1000, np.random.default_rng(0))
    assert set(run_ids[s.pos_indices]) <= set(np.flatnonzero(wins))
    whole = sample_training_set(pre, actions, run_ids, wins, 1000, np.random.default_rng(0),
                                mode="whole")
    assert set(run_ids[whole.pos_indices]) - set(np.flatnonzero(wins))  # losers used too
    assert len(whole.pos_indices) == 500  # still sized by the win rate


def test_class_proportions_follow_eq4_and_eq6():
    # winning run 0: all action 0; winning run 1: half 1 half 2; run 2 loses (all 3)
    actions = np.array([0] * 10 + [1] * 5 + [2] * 5 + [3] * 10)
    run_ids = np.repeat([0, 1, 2], [10, 10, 10])
    wins = np.array([True, True, False])
    pre = np.array([0] * 100 + [1] * 300 + [2] * 100 + [3] * 500)
    s = sample_training_set(pre, actions, run_ids, wins, 3000, np.random.default_rng(0),
                            win_rate=0.5)
    # q = per-run average over winning runs: (1,0,0,0) and (0,.5,.5,0) -> (.5,.25,.25,0)
    np.testing.assert_allclose(s.pos_class_shares, [0.5, 0.25, 0.25, 0.0])
    pos_counts = np.bincount(actions[s.pos_indices], minlength=4)
    assert pos_counts.tolist() == [750, 375, 375, 0]
    pre_counts = np.bincount(pre[s.pre_indices], minlength=4)
    assert pre_counts.tolist() == [150, 450, 150, 750]


def test_run_action_distribution_is_eq4():
    actions = np.array([0, 0, 1, 1, 1, 1])
    run_ids = np.array([0, 0, 1, 1, 1, 1])
    dist = run_action_distribution(actions, run_ids, np.array([0, 1]), 2)
    np.testing.assert_allclose(dist, [0.5, 0.5])  # each run weighs the same


def test_draws_are_uniform_within_a_class_not_index_weighted():
    labels = np.zeros(1000, dtype=np.int64)
    drawn = draw_by_class(labels, np.array([200_000]), np.random.default_rng(0))
    counts = np.bincount(drawn, minlength=1000)
    # multinomial(range(n)) would favour high indices ~ index; uniform keeps halves equal
    low, high = counts[:500].sum(), counts[500:].sum()
    assert abs(low - high) / 200_000 < 0.02
    assert counts[0] > 0


def test_draws_without_replacement_when_enough_rows():
    labels = np.array([0] * 50 + [1] * 5)
    drawn = draw_by_class(labels, np.array([50, 10]), np.random.default_rng(0))
    zeros = drawn[labels[drawn] == 0]
    assert len(np.unique(zeros)) == 50
    assert len(drawn[labels[drawn] == 1]) == 10  # with replacement only for the small class


def test_sampling_is_deterministic_per_seed():
    actions, run_ids = _pos()
    wins = np.array([True] * 4 + [False] * 6)
    pre = np.random.default_rng(3).integers(0, 4, 500)
    a = sample_training_set(pre, actions, run_ids, wins, 300, np.random.default_rng(7))
    b = sample_training_set(pre, actions, run_ids, wins, 300, np.random.default_rng(7))
    c = sample_training_set(pre, actions, run_ids, wins, 300, np.random.default_rng(8))
    assert np.array_equal(a.pre_indices, b.pre_indices)
    assert np.array_equal(a.pos_indices, b.pos_indices)
    assert not np.array_equal(a.pre_indices, c.pre_indices)


# -- metrics -----------------------------------------------------------------------------------


def test_performance_on_hand_made_returns():
    p = performance(np.array([10.0, 0.0, 5.0]), expert=10.0, random=0.0)
    np.testing.assert_allclose(p, [1.0, 0.0, 0.5])
    # per-episode references (per maze layout), then averaged
    returns = np.array([0.9, 0.5, -1.0])
    expert = np.array([0.9, 0.9, 0.8])
    random = np.array([0.1, 0.5, 0.0])
    m = summarize(returns, np.array([True, True, False]), expert, random)
    assert m["performance"] == pytest.approx((1.0 + 0.0 + (-1.25)) / 3)
    assert m["aer"] == pytest.approx(0.4 / 3)
    assert m["success_rate"] == pytest.approx(2 / 3)
    with pytest.raises(ValueError):
        performance(np.array([1.0]), 1.0, 1.0)


def test_other_datasets_make_another_run(tmp_path):
    """A finished run asked for with other pre-demonstrations is not handed back as a result."""
    from abco_train.harness.run_folder import config_differences, finished_result

    (tmp_path / "config.json").write_text(json.dumps({"env": "Acrobot-v1", "pre_data": None}))
    final = {"env": "Acrobot-v1", "method": "abco", "seed": 0, "status": "ok",
             "episodes": {"performance": 1.0, "aer": -80.0, "success_rate": 1.0, "episodes": 3}}
    (tmp_path / "final.json").write_text(json.dumps(final))
    same = {"env": "Acrobot-v1", "pre_data": None, "run_dir": "elsewhere", "quiet": True,
            "method": "abco", "seed": 0}
    held = {"env": "Acrobot-v1", "pre_data": "abco/acrobot-pre-held-v0"}
    assert config_differences(tmp_path, same) == []
    assert finished_result(tmp_path, same) == final
    assert config_differences(tmp_path, held) == ["pre_data"]
    assert finished_result(tmp_path, held) is None


@pytest.mark.parametrize(("space", "idm_input"), [
    (spaces.Box(-1.0, 1.0, (6,)), "difference"),
    (spaces.Box(0, 255, (12, 12, 3), dtype=np.uint8), "difference"),
    (spaces.Box(0, 255, (12, 12, 3), dtype=np.uint8), "pair"),
])  # fmt: skip
def test_an_idm_reads_pair_inputs_built_once(space, idm_input) -> None:
    """``from_input(pair_input(s, s'))`` is the forward pass to the bit, and two batches' inputs
    stacked are the concatenated batches' input: DILO builds them once for its online and its
    target utility. Four unrelated batches: no frame of one pair stands for another's."""
    torch.manual_seed(0)
    _, idm = build_networks(space, 4, attention=False, idm_input=idm_input)
    idm.eval()  # no dropout draws between the passes compared
    a, b, c, d = (torch.as_tensor(np.stack([space.sample() for _ in range(5)])) for _ in range(4))
    with torch.no_grad():
        assert torch.equal(idm.from_input(idm.pair_input(a, b)), idm(a, b))
        both = idm.stacked_input(idm.pair_input(a, b), idm.pair_input(c, d))
        assert torch.equal(both, idm.pair_input(torch.cat([a, c]), torch.cat([b, d])))
        assert torch.equal(idm.from_input(both), idm(torch.cat([a, c]), torch.cat([b, d])))

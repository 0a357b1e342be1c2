"""DILO and LAPO: their losses on hand-checked cases, every env, interactions, resume, options."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from train_testing import tiny_config

import abco_envs
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.loop import train
from abco_train.harness.training_data import load_training_data
from abco_train.methods.dilo.method import DILO, dual_loss, f_star, orthogonal_gradient
from abco_train.methods.dilo.options import DILOOptions
from abco_train.methods.lapo.method import LAPO
from abco_train.methods.lapo.networks import VectorQuantiser, linear_probe_accuracy
from abco_train.methods.lapo.options import LAPOOptions
from abco_train.methods.offline import iteration_steps, state_network, triples
from abco_train.methods.registry import available, get_method, resolve_config

ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)
#: A few gradient steps of each.
TINY = {"dilo": {"steps": 3, "rounds": 2},
        "lapo": {"model_steps": 3, "policy_steps": 3, "decoder_epochs": 1, "rounds": 2,
                 "schedule": "steps"}}


def _config(method, env_id, tiny_data, run_dir, **changes):
    options = {**TINY[method], **changes.pop("method_options", {})}
    return tiny_config(env_id, method, tiny_data, run_dir, method_options=options,
                       device="cpu", **changes)  # fmt: skip


def _numbers(run_dir):
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    final = json.loads((run_dir / "final.json").read_text())
    final.pop("seconds")
    return [(r["train"], r["eval"], r["interactions"]) for r in rows], final


def test_both_are_registered_methods():
    assert {"dilo", "lapo"} <= set(available())
    assert get_method("dilo") is DILO and get_method("lapo") is LAPO


# -- DILO's losses ------------------------------------------------------------------------------


def test_f_star_is_the_pearson_conjugate_of_the_authors_code():
    x = torch.tensor([-6.0, -2.0, -1.0, 0.0, 1.0, 4.0])
    # x + x^2 / 4 from -2 up, -1 below
    assert f_star(x).tolist() == [-1.0, -1.0, -0.75, 0.0, 1.25, 8.0]


def test_dual_loss_weighs_expert_and_offline_residuals():
    expert, offline = torch.tensor([2.0, 0.0]), torch.tensor([1.0, -4.0])
    # beta * mean f*(e) + (1 - beta) * (mean f*(o) - mean o)
    want = 0.25 * (3.0 + 0.0) / 2 + 0.75 * ((1.25 - 1.0) / 2 - (-3.0) / 2)
    assert dual_loss(expert, offline, 0.25).item() == pytest.approx(want)


def test_orthogonal_gradient_adds_the_part_of_g_b_orthogonal_to_g_f():
    g_f = [torch.tensor([3.0, 0.0]), torch.tensor([0.0])]
    g_b = [torch.tensor([1.0, 2.0]), torch.tensor([5.0])]
    out = torch.cat(orthogonal_gradient(g_f, g_b))
    flat_f = torch.cat(g_f)
    assert torch.allclose(out, torch.tensor([3.0, 2.0, 5.0]))
    assert float((out - flat_f) @ flat_f) == pytest.approx(0.0)  # the added part is orthogonal


def test_triples_keep_transitions_whose_next_state_starts_one():
    obs_t = np.array([0, 1, 2, 4, 5, 6, 7])  # episodes of rows 0-3 and 4-8
    assert triples(obs_t).tolist() == [0, 1, 3, 4, 5]
    assert [iteration_steps(7, i, 3) for i in range(3)] == [2, 2, 3]


def test_dilo_weights_rise_with_the_utility(tiny_data, tmp_path):
    cfg = resolve_config(_config("dilo", "CartPole-v1", tiny_data, tmp_path))
    method = DILO(cfg, load_training_data(cfg), np.random.default_rng(0))
    with torch.no_grad():
        head = method.value.head  # the IDM network's last layer: V = bias
        head.weight.zero_()
        head.bias.copy_(torch.tensor([10.0, 20.0]))
    s, s1 = method.data_t.pre_pairs(torch.arange(4))
    # min of the twin heads, exp(tau V), clipped
    assert torch.allclose(method.weights(s, s1), torch.full((4,), np.exp(0.06 * 10.0)))
    method.options.weight_clip = 1.5
    assert torch.equal(method.weights(s, s1), torch.full((4,), 1.5))


def _one_pass_value_step(method: DILO, pre_idx: torch.Tensor, expert_idx: torch.Tensor) -> None:
    """DILO's value step written with one online pass over both pairs of every triple."""
    opts, params = method.options, list(method.value.parameters())
    s, s1, s2 = method._triples(method.pre_rows[pre_idx], method.expert_rows[expert_idx])
    n, n_pre = len(s), len(pre_idx)
    first, second = torch.cat([s, s1]), torch.cat([s1, s2])
    online = method.value(first, second)
    with torch.no_grad():
        target = method.target(first, second).min(1, keepdim=True).values
    fwd, bwd = opts.gamma * target[n:] - online[:n], opts.gamma * online[n:] - target[:n]
    forward = opts.lam * dual_loss(fwd[n_pre:], fwd[:n_pre], opts.beta)
    backward = opts.lam * opts.eta * dual_loss(bwd[n_pre:], bwd[:n_pre], opts.beta)
    g_f = torch.autograd.grad(forward, params, retain_graph=True)
    g_b = torch.autograd.grad(backward, params, retain_graph=True)
    g_v = torch.autograd.grad((1 - opts.lam) * online[:n_pre].mean(), params)
    method.value_opt.zero_grad(set_to_none=True)
    for p, g, v in zip(params, orthogonal_gradient(list(g_f), list(g_b)), g_v):
        p.grad = g + v
    method.value_opt.step()


@pytest.mark.parametrize("env_id", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_dilo_value_step_is_the_one_pass_update(env_id, tiny_data, tmp_path):
    """Two online passes (the pairs (s, s') and (s', s'') apart) give the update of one pass
    over both: the same gradients, summed in another order."""
    # with the attention (an option): its gates at 0.5, so every parameter has a gradient
    cfg = resolve_config(_config("dilo", env_id, tiny_data, tmp_path, attention=True))
    methods = [DILO(cfg, load_training_data(cfg), np.random.default_rng(0)) for _ in range(2)]
    for p in methods[0].value.parameters():
        if p.ndim == 0:
            torch.nn.init.constant_(p, 0.5)
    for m in methods:  # the same weights in both, the target a copy of V
        m.value.load_state_dict(methods[0].value.state_dict())
        m.target.load_state_dict(methods[0].value.state_dict())
        # plain steps: Adam's first step is lr * sign(g), which would blow up last-bit noise
        m.value_opt = torch.optim.SGD(m.value.parameters(), lr=0.1)
        m.value.eval()  # no dropout masks, which the two would draw differently
    before = [p.detach().clone() for p in methods[0].value.parameters()]
    pre_idx, expert_idx = torch.tensor([0, 2, 1]), torch.tensor([1, 0])
    methods[0]._value_step(pre_idx, expert_idx)
    _one_pass_value_step(methods[1], pre_idx, expert_idx)
    for a, b, p in zip(methods[0].value.parameters(), methods[1].value.parameters(), before):
        # the steps agree to a percent (the convolutions' sums differ with the batch's size,
        # and the orthogonal projection divides by |g_f|^2); a wrong pair would not
        torch.testing.assert_close(a - p, b - p, rtol=1e-2, atol=1e-6)
    moved = [not torch.equal(v, t) for v, t in zip(methods[0].value.parameters(),
                                                   methods[0].target.parameters())]
    assert sum(moved) > len(moved) // 2  # V stepped (the target only followed it by Polyak)


@pytest.mark.parametrize("env_id", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_lapo_policy_targets_are_the_frozen_idms_latents(env_id, tiny_data, tmp_path):
    """Stage 2 regresses on ``z = IDM(s, s')`` computed once after stage 1: the values a
    minibatch's own pass gives, recomputed after the IDM changes (stage 1, a restore)."""
    cfg = resolve_config(_config("lapo", env_id, tiny_data, tmp_path))
    method = LAPO(cfg, load_training_data(cfg), np.random.default_rng(0))
    method.train_iteration(0)
    rows = torch.tensor([2, 0, 1, 2])
    with torch.no_grad():
        method.idm.eval()
        direct = method.idm(*method.data_t.expert_pairs(rows))
    torch.testing.assert_close(method._expert_latents()[rows], direct, rtol=1e-5, atol=1e-6)
    state = copy.deepcopy(method.state_dict())
    with torch.no_grad():
        for p in method.idm.parameters():
            p.add_(1.0)
    method._expert_z = None  # refilled from the changed IDM
    assert not torch.allclose(method._expert_latents()[rows], direct)
    method.load_state_dict(state)  # dropped again: the restored IDM's latents
    torch.testing.assert_close(method._expert_latents()[rows], direct, rtol=1e-5, atol=1e-6)


# -- LAPO's bottleneck --------------------------------------------------------------------------


def test_vector_quantiser_snaps_to_codes_and_passes_gradients_straight_through():
    vq = VectorQuantiser(codebooks=2, slots=1, code_dim=2, codes=2).eval()
    with torch.no_grad():
        vq.embedding.copy_(torch.tensor([[[0.0, 0.0], [1.0, 1.0]], [[5.0, 5.0], [-5.0, 0.0]]]))
    z = torch.tensor([[0.9, 0.8, -4.0, 1.0]], requires_grad=True)
    q, loss, codes = vq(z)
    assert codes.tolist() == [[1, 1]]
    assert torch.allclose(q, torch.tensor([[1.0, 1.0, -5.0, 0.0]]))
    (q * torch.tensor([1.0, 2.0, 3.0, 4.0])).sum().backward()
    assert z.grad is not None and z.grad.tolist() == [[1.0, 2.0, 3.0, 4.0]]  # straight through
    # the commitment loss: weight * mean squared distance to the (fixed) codes
    assert loss.item() == pytest.approx(0.05 * (0.01 + 0.04 + 1.0 + 1.0) / 4)


def test_vector_quantiser_codes_follow_their_vectors_in_training():
    torch.manual_seed(0)
    vq = VectorQuantiser(codebooks=1, slots=1, code_dim=2, codes=2, decay=0.5).train()
    before = vq.embedding.clone()
    z = torch.tensor([[3.0, 3.0]]).repeat(8, 1)
    for _ in range(20):
        _, _, codes = vq(z)
    code = int(codes[0, 0])
    assert torch.allclose(vq.embedding[0, code], torch.tensor([3.0, 3.0]), atol=1e-3)
    assert not torch.allclose(before[0, code], vq.embedding[0, code])
    vq.eval()  # evaluation moves no code
    after = vq.embedding.clone()
    vq(torch.randn(4, 2))
    assert torch.equal(vq.embedding, after)


def test_linear_probe_reads_separable_latents_and_not_noise():
    rng = np.random.default_rng(0)
    actions = torch.from_numpy(rng.integers(0, 3, 600))
    separable = torch.nn.functional.one_hot(actions, 3).float() + 0.1 * torch.randn(600, 3)
    assert linear_probe_accuracy(separable, actions, 3, rng) == 1.0
    assert linear_probe_accuracy(torch.randn(600, 3), actions, 3, rng) < 0.5


# -- both, end to end ---------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["dilo", "lapo"])
@pytest.mark.parametrize("env_id", ENVS)
def test_runs_on_every_env(method, env_id, tiny_data, tmp_path):
    final = train(_config(method, env_id, tiny_data, tmp_path))
    key = "train/paper" if env_id in abco_envs.MAZE_IDS else "episodes"
    assert final is not None and final["status"] == "ok"
    assert np.isfinite(final[key]["performance"])
    rows = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 2  # iterations 0 and 1, each evaluated
    wanted = {"dilo": "weight_ratio", "lapo": "probe_accuracy"}[method]
    assert all(np.isfinite(r["train"][wanted]) for r in rows)


@pytest.mark.parametrize("method", ["dilo", "lapo"])
def test_interactions_are_the_pre_demonstrations_and_nothing_online(method, tiny_data,
                                                                    tmp_path):  # fmt: skip
    cfg = _config(method, "CartPole-v1", tiny_data, tmp_path / "all")
    n_pre = len(load_training_data(resolve_config(cfg)).pre_t)
    final = train(cfg)
    assert final is not None
    assert final["interactions"] == {"pre_demonstration": n_pre, "post_demonstration": 0,
                                     "rl": 0, "remapping": 0}  # fmt: skip
    budget = train(_config(method, "CartPole-v1", tiny_data, tmp_path / "budget", budget=100))
    assert budget is not None and budget["interactions"]["pre_demonstration"] == 100
    # the budget is spent on the data; its gradient steps are not cut: every iteration runs
    rows = [json.loads(x) for x in (tmp_path / "budget" / "metrics.jsonl").read_text()
            .splitlines()]  # fmt: skip
    assert len(rows) == 2 and not any("stopped" in r for r in rows)
    assert budget.get("stopped") is None


@pytest.mark.parametrize("method", ["dilo", "lapo"])
def test_a_resumed_run_equals_an_uninterrupted_one(method, tiny_data, tmp_path):
    straight = _config(method, "AbcoMaze3x3-v0", tiny_data, tmp_path / "straight")
    train(straight)
    resumed = _config(method, "AbcoMaze3x3-v0", tiny_data, tmp_path / "resumed")
    assert train(resumed, stop_after=1) is None
    train(resumed)
    assert _numbers(tmp_path / "straight") == _numbers(tmp_path / "resumed")
    other = _config(method, "AbcoMaze3x3-v0", tiny_data, tmp_path / "other", seed=1)
    train(other)
    assert _numbers(tmp_path / "other")[0] != _numbers(tmp_path / "straight")[0]


@pytest.mark.parametrize("method", ["dilo", "lapo"])
@pytest.mark.parametrize("env_id", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_no_attention_by_default_as_in_their_papers(method, env_id, tmp_path):
    """Their papers' networks carry no self-attention (ABCO's own); ``--attention`` adds it."""
    assert resolve_config(RunConfig(env=env_id, method=method, run_dir=str(tmp_path))
                          ).attention is False  # fmt: skip
    assert resolve_config(RunConfig(env=env_id, method=method, run_dir=str(tmp_path),
                                    attention=True)).attention is True  # fmt: skip


def test_options_defaults_and_checks():
    dilo = DILOOptions.for_run(RunConfig(env="CartPole-v1", lr=0.01))
    assert dilo.value_lr == dilo.policy_lr == 0.01  # the run's learning rate where not given
    assert DILOOptions.for_run(RunConfig(env="AbcoMaze5x5-v0")).steps == 2000
    assert LAPOOptions.for_run(RunConfig(env="CartPole-v1")).latent_dim == 128
    with pytest.raises(ConfigError, match="unknown lapo option"):
        LAPOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"steps": 3}))
    with pytest.raises(ConfigError, match="--dilo-beta must be <= 1.0"):
        DILOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"beta": 2.0}))


def test_the_options_modules_import_no_torch():
    code = ("import sys; import abco_train.methods.dilo.options, abco_train.methods.lapo.options;"
            " print('torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.stdout.strip() == "False", done.stderr


def test_a_network_with_other_outputs_reads_the_maze_without_the_planner(tiny_data, tmp_path):
    cfg = resolve_config(_config("lapo", "AbcoMaze5x5-v0", tiny_data, tmp_path,
                                 arch="cellplan"))  # fmt: skip
    data = load_training_data(cfg)
    stats = {"grid": 5}
    acting = state_network(cfg, data, stats, data.n_actions, actions=True)
    latent = state_network(cfg, data, stats, 7)
    assert getattr(acting.encoder, "planner", None) is not None
    assert getattr(latent.encoder, "planner", None) is None
    frames = torch.zeros(2, *data.observation_space.shape, dtype=torch.uint8)
    assert latent(frames).shape == (2, 7) and acting(frames).shape == (2, data.n_actions)

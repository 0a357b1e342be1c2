"""ILPO: the min-over-latents loss, remapping counted, every env, same seed same run."""

from __future__ import annotations

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch
from train_testing import tiny_config

import abco_envs
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.loop import train
from abco_train.harness.runtime import seed_everything
from abco_train.harness.training_data import load_training_data
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.methods.ilpo.method import (
    ILPO,
    ImageForwardModel,
    expected_prediction_loss,
    min_over_latents_loss,
)
from abco_train.methods.ilpo.options import OPTION_DEFAULTS, ILPOOptions
from abco_train.methods.registry import available, resolve_config
from abco_train.networks.cells import CellAverage

ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)
#: A tiny budget: a few gradient steps, a few remapping steps.
TINY = {"train_steps": 4, "remap_steps": 24, "remap_envs": 4, "remap_epochs": 2}


#: Mazes train pi after G (``policy_steps``): a few steps of each.
TINY_MAZE = {"policy_steps": 4}


def _config(env_id, tiny_data, run_dir, **changes):
    options = {**TINY, **(TINY_MAZE if env_id in abco_envs.MAZE_IDS else {})}
    return tiny_config(env_id, "ilpo", tiny_data, run_dir, method_options=options,
                       device="cpu", **changes)  # fmt: skip


def test_ilpo_is_a_registered_method():
    assert "ilpo" in available()


# -- the losses -------------------------------------------------------------------------------


def test_min_over_latents_loss_is_zero_when_one_latent_predicts_the_target():
    pred = torch.tensor([[[1.0, -2.0, 0.5], [3.0, 3.0, 3.0]]], requires_grad=True)
    target = pred[0, 0].detach().clone()[None]
    loss, best = min_over_latents_loss(pred, target)
    assert loss.item() == 0.0 and best.tolist() == [0]
    loss.backward()
    assert torch.count_nonzero(pred.grad) == 0


def test_min_over_latents_loss_moves_only_the_best_latent():
    pred = torch.tensor([[[1.0, 1.0], [5.0, -5.0]],
                         [[0.0, 0.0], [2.0, 2.0]]], requires_grad=True)  # fmt: skip
    target = torch.tensor([[1.5, 0.5], [2.0, 1.0]])  # row 0 nearest latent 0, row 1 latent 1
    loss, best = min_over_latents_loss(pred, target)
    assert best.tolist() == [0, 1]
    # mean over features, then over the batch: ((0.25 + 0.25) / 2 + (0 + 1) / 2) / 2
    assert loss.item() == pytest.approx(0.375)
    loss.backward()
    grad = pred.grad
    assert torch.count_nonzero(grad[0, 1]) == 0 and torch.count_nonzero(grad[1, 0]) == 0
    assert torch.count_nonzero(grad[0, 0]) == 2 and torch.count_nonzero(grad[1, 1]) == 1
    # d/dpred of ((pred - target)^2).mean() / B: 2 (pred - target) / (D * B)
    assert torch.allclose(grad[0, 0], torch.tensor([-0.25, 0.25]))


def test_relaxed_min_loss_gives_every_latent_a_little_gradient():
    pred = torch.tensor([[[0.0], [4.0]]], requires_grad=True)
    loss, _ = min_over_latents_loss(pred, torch.tensor([[1.0]]), relax=0.1)
    assert loss.item() == pytest.approx(0.9 * 1.0 + 0.1 * (1.0 + 9.0) / 2)
    loss.backward()
    assert torch.count_nonzero(pred.grad) == 2


def test_expected_prediction_loss_trains_the_policy_not_the_predictions():
    pred = torch.tensor([[[0.0, 0.0], [2.0, 2.0]]], requires_grad=True)
    logits = torch.zeros(1, 2, requires_grad=True)
    target = torch.tensor([[2.0, 2.0]])
    loss = expected_prediction_loss(logits.softmax(1), pred, target)
    assert loss.item() == pytest.approx(1.0)  # the expectation (1, 1) is 1 off in each feature
    loss.backward()
    assert pred.grad is None
    assert logits.grad[0, 1] < 0 < logits.grad[0, 0]  # mass moves to the latent that fits
    pred.grad = None
    expected_prediction_loss(logits.softmax(1), pred, target, pred_weight=0.5).backward()
    assert pred.grad is not None and torch.count_nonzero(pred.grad) > 0


# -- runs -----------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", ENVS)
def test_ilpo_runs_on_every_env(env_id, tiny_data, tmp_path):
    final = train(_config(env_id, tiny_data, tmp_path))
    key = "train/paper" if env_id in abco_envs.MAZE_IDS else "episodes"
    assert final["status"] == "ok"
    assert np.isfinite(final[key]["performance"])
    counts = final["interactions"]
    assert set(counts) == set(INTERACTION_KINDS)
    assert counts["remapping"] > 0
    assert counts["pre_demonstration"] == counts["post_demonstration"] == counts["rl"] == 0


def test_remapping_steps_are_counted_and_no_pre_demonstrations(tiny_data, tmp_path):
    cfg = _config("AbcoMaze3x3-v0", tiny_data, tmp_path, iterations=2)
    final = train(cfg)
    stored = json.loads((tmp_path / "final.json").read_text())
    rows = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    taken = [r["train"]["remap_steps"] for r in rows]
    assert len(taken) == 3 and all(0 < t <= TINY["remap_steps"] for t in taken)
    assert stored["interactions"]["remapping"] == sum(taken) == final["interactions"]["remapping"]
    assert stored["interactions"]["pre_demonstration"] == 0
    assert [r["interactions"]["remapping"] for r in rows] == np.cumsum(taken).tolist()


def test_a_run_without_remapping_steps_counts_none(tiny_data, tmp_path):
    cfg = _config("CartPole-v1", tiny_data, tmp_path)
    cfg.method_options["remap_steps"] = 0
    assert train(cfg)["interactions"] == dict.fromkeys(INTERACTION_KINDS, 0)


def _numbers(run_dir):
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    final = json.loads((run_dir / "final.json").read_text())
    final.pop("seconds")
    return [(r["train"], r["eval"], r["interactions"]) for r in rows], final


@pytest.mark.parametrize("env_id", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_same_seed_same_run(env_id, tiny_data, tmp_path):
    train(_config(env_id, tiny_data, tmp_path / "a"))
    train(_config(env_id, tiny_data, tmp_path / "b"))
    train(_config(env_id, tiny_data, tmp_path / "c", seed=1))
    assert _numbers(tmp_path / "a") == _numbers(tmp_path / "b")
    assert _numbers(tmp_path / "a")[0] != _numbers(tmp_path / "c")[0]


def test_a_resumed_run_equals_an_uninterrupted_one(tiny_data, tmp_path):
    straight = _config("AbcoMaze3x3-v0", tiny_data, tmp_path / "straight")
    train(straight)
    resumed = _config("AbcoMaze3x3-v0", tiny_data, tmp_path / "resumed")
    assert train(resumed, stop_after=1) is None
    train(resumed)
    assert _numbers(tmp_path / "straight") == _numbers(tmp_path / "resumed")


def test_ilpo_options(tiny_data, tmp_path):
    cfg = resolve_config(_config("Acrobot-v1", tiny_data, tmp_path))
    data = load_training_data(cfg)
    method = ILPO(cfg, data, seed_everything(0))
    assert isinstance(method.options, ILPOOptions)
    assert method.k == data.n_actions == 3  # default: as many latents as actions
    assert method.options.remap_margin == 0.1  # classic control: only clearly explained steps
    assert method.interactions["pre_demonstration"] == 0
    # Acrobot's own default on top of classic control's (CartPole keeps 500 steps a round)
    assert ILPO.resolve_options(cfg.replace(method_options={})).remap_steps == 1000
    cartpole = resolve_config(_config("CartPole-v1", tiny_data, tmp_path))
    assert ILPO.resolve_options(cartpole.replace(method_options={})).remap_steps == 500
    cfg.method_options["latents"] = 5
    assert ILPO(cfg, data, seed_everything(0)).k == 5
    for bad, message in (
        ({"latent": 3}, "unknown ilpo option"),
        ({"latents": 1}, "--ilpo-latents must be >= 2, got 1"),
        ({"latents": True}, "--ilpo-latents must be an integer"),
        ({"remap": "nearest"}, "--ilpo-remap must be one of state, table"),
        ({"remap_epsilon": 2.0}, "--ilpo-remap-epsilon must be <= 1.0, got 2.0"),
        ({"remap_margin": 0.0}, "--ilpo-remap-margin must be > 0.0"),
        ({"hidden": None}, "--ilpo-hidden must be set, got null"),
        ({"target": "cells"}, "--ilpo-target cells is for maze"),  # cells: mazes only
    ):
        with pytest.raises(ConfigError, match=message):
            ILPO(cfg.replace(method_options=bad), data, seed_everything(0))


def test_resolved_options_are_the_whole_table():
    """The run's config holds every option resolved: the env's action count for ``latents``,
    ``4 n^2`` for a maze's ``remap_max_steps``, and the env's own defaults."""
    options = ILPOOptions.for_run(RunConfig(env="AbcoMaze3x3-v0"))
    assert set(options.to_dict()) == set(OPTION_DEFAULTS["maze"])
    assert (options.latents, options.remap_max_steps, options.pool) == (4, 36, 8)
    ten = ILPOOptions.for_run(RunConfig(env="AbcoMaze10x10-v0", method_options={"latents": 6}))
    assert (ten.latents, ten.target, ten.remap, ten.remap_max_steps) == (6, "pooled", "table",
                                                                         400)  # fmt: skip
    classic = ILPOOptions.for_run(RunConfig(env="MountainCar-v0"))
    assert (classic.latents, classic.remap_max_steps, classic.policy_steps) == (3, None, None)


@pytest.mark.parametrize(("env", "preset", "target"), [
    ("AbcoMaze10x10-v0", "cpu", "pooled"),  # every method reads frames through the CNN
    ("AbcoMaze5x5-v0", "general", "cells"),  # every method reads the maze cell by cell
    ("AbcoMaze3x3-v0", "cpu", "pooled"),
    ("CartPole-v1", "cpu", "pooled"),
])  # fmt: skip
def test_the_cell_target_goes_with_a_cell_encoder(env, preset, target):
    """ILPO's forward model sees the maze's cells exactly where the run's encoder does, the
    other methods' included: a structure prior all methods of a task share, or none."""
    cfg = resolve_config(RunConfig(env=env, method="ilpo", preset=preset))
    assert cfg.method_options["target"] == target
    assert (target == "cells") == (cfg.arch in ("cellnet", "cellplan"))
    chosen = resolve_config(RunConfig(env="AbcoMaze10x10-v0", method="ilpo",
                                      method_options={"target": "cells"}))  # fmt: skip
    assert chosen.method_options["target"] == "cells"  # still an option of its own


def test_the_options_module_imports_no_torch():
    code = ("import sys, abco_train.methods.ilpo.options as o; "
            "assert 'torch' not in sys.modules; print(o.ILPOOptions.flag_prefix)")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ilpo-"


def test_act_is_the_remapped_argmax_latent(tiny_data, tmp_path):
    cfg = resolve_config(_config("CartPole-v1", tiny_data, tmp_path))
    cfg.method_options["remap"] = "table"
    method = ILPO(cfg, load_training_data(cfg), seed_everything(0))
    head = method.net.policy[-1]
    with torch.no_grad():  # a latent policy that always picks latent 1
        head.weight.zero_()
        head.bias.copy_(torch.tensor([0.0, 5.0]))
    method.remapping.counts[:] = [[0, 3], [7, 1]]  # latent 1 is mostly action 0
    obs = np.zeros((6, 4), dtype=np.float32)
    assert (method.act(obs) == 0).all()
    method.remapping.counts[:] = [[0, 3], [1, 7]]
    assert (method.act(obs) == 1).all()


# -- pi trained after G (policy_steps), and what the diagnostics measure ---------------------


def _method(env_id, tiny_data, tmp_path, **options):
    cfg = resolve_config(_config(env_id, tiny_data, tmp_path))
    cfg.method_options.update(options)
    return ILPO(cfg, load_training_data(cfg), seed_everything(0))


def test_policy_steps_defaults_and_checks(tiny_data, tmp_path):
    cfg = resolve_config(_config("AbcoMaze5x5-v0", tiny_data, tmp_path))
    data = load_training_data(cfg)
    cfg.method_options.pop("policy_steps")
    assert ILPO(cfg, data, seed_everything(0)).options.policy_steps == 1000  # mazes: in turn
    assert _method("Acrobot-v1", tiny_data, tmp_path).options.policy_steps is None  # joint
    for bad in (0, -3, 2.5, True, "10"):
        with pytest.raises(ConfigError, match="--ilpo-policy-steps"):
            ILPO(cfg.replace(method_options={"policy_steps": bad}), data, seed_everything(0))


def _snapshot(module):
    return [p.detach().clone() for p in module.parameters()]


def _changed(module, before):
    return any(not torch.equal(p, q) for p, q in zip(module.parameters(), before, strict=True))


def test_policy_steps_trains_g_then_pi_against_the_fixed_g(tiny_data, tmp_path):
    method = _method("AbcoMaze3x3-v0", tiny_data, tmp_path)
    g, pi = method.net.forward_model, method.net.policy
    g0, pi0 = _snapshot(g), _snapshot(pi)
    stats = method._train_latent_model(5, 1)  # G five steps, pi one
    assert stats["train_steps"] == 5 and stats["policy_steps"] == 1
    assert _changed(g, g0) and _changed(pi, pi0)
    # the G phase leaves pi alone and the pi phase leaves G alone
    method = _method("AbcoMaze3x3-v0", tiny_data, tmp_path)
    g, pi = method.net.forward_model, method.net.policy
    pi0 = _snapshot(pi)
    calls = []
    real_step = method.opt.step

    def step():
        calls.append((_snapshot(g), _snapshot(pi)))
        real_step()

    method.opt.step = step
    method._train_latent_model(3, 2)
    calls.append((_snapshot(g), _snapshot(pi)))
    for before, after in zip(calls[:3], calls[1:4], strict=True):  # G phase: pi unchanged
        assert all(torch.equal(p, q) for p, q in zip(before[1], after[1], strict=True))
    for before, after in zip(calls[3:5], calls[4:6], strict=True):  # pi phase: G unchanged
        assert all(torch.equal(p, q) for p, q in zip(before[0], after[0], strict=True))
        assert any(not torch.equal(p, q) for p, q in zip(before[1], after[1], strict=True))


def test_policy_action_accuracy_scores_what_act_does(tiny_data, tmp_path):
    method = _method("CartPole-v1", tiny_data, tmp_path, remap="table")
    head = method.net.policy[-1]
    with torch.no_grad():  # a broken latent policy: latent 1 in every state
        head.weight.zero_()
        head.bias.copy_(torch.tensor([0.0, 5.0]))
    method.remapping.counts[:] = [[9, 0], [0, 9]]  # latent 0 is action 0, latent 1 action 1
    stats = method._expert_statistics()
    s = method.expert_obs[method.expert_t].numpy()
    truth = method.data.expert_eval_actions
    assert stats["policy_latent_usage"] == [0.0, 1.0]
    assert (method.act(s) == 1).all()
    assert stats["policy_action_accuracy"] == pytest.approx(float((truth == 1).mean()))
    # the inferred labels go through z*, not through pi: they may look healthy regardless
    labels = method.expert_labels()
    assert stats["expert_label_accuracy"] == pytest.approx(float((labels == truth).mean()))
    z, _, _ = method._latents_of(method.expert_obs[method.expert_t],
                                 method.expert_obs[method.expert_t + 1])  # fmt: skip
    assert (labels == z.numpy()).all()


# -- the cell-aligned target (``target="cells"``) -----------------------------------------------


def test_cell_average_takes_each_rendered_cell_exactly():
    """Cells 6 or 7 pixels wide (10x10 in 64 pixels): each output is its own cell's mean."""
    edges = np.round(np.linspace(0, 64, 11)).astype(int)
    assert set(np.diff(edges)) == {6, 7}
    values = torch.arange(100, dtype=torch.float32).reshape(10, 10)
    image = torch.zeros(1, 1, 64, 64)
    for i in range(10):
        for j in range(10):
            image[0, 0, edges[i] : edges[i + 1], edges[j] : edges[j + 1]] = values[i, j]
    assert torch.allclose(CellAverage(10, 64, 64)(image)[0, 0], values)
    sizes = torch.from_numpy(np.diff(edges).astype(np.float32))
    total = CellAverage(10, 64, 64, total=True)(torch.ones(1, 1, 64, 64))[0, 0]
    assert torch.equal(total, sizes[:, None] * sizes[None, :])  # total: each cell's pixel sum


@pytest.mark.parametrize("cells", [None, 10])
def test_forward_model_draws_its_initial_weights_in_its_published_order(cells):
    """Torch draws weights in construction order, so the order fixes every ILPO maze run:
    both paths (pooled: 3x3, 5x5; cells: 10x10) draw the embedding, the head's last
    convolution, the latent, then the head's first convolution (the pooled path's order was
    re-validated on the headline track's validation seeds: 0.597 against 0.512)."""
    torch.manual_seed(0)
    model = ImageForwardModel((64, 64, 3), latents=4, pool=4, channels=8, cells=cells)
    torch.manual_seed(0)
    for layer in model.embedding:
        if isinstance(layer, torch.nn.Conv2d):
            torch.nn.Conv2d(layer.in_channels, layer.out_channels, layer.kernel_size)
    last = model.head[3]
    last_again = torch.nn.Conv2d(last.in_channels, last.out_channels, last.kernel_size)
    latent = torch.randn(4, 8)
    first = torch.nn.Conv2d(8, 8, 3)
    assert torch.equal(last_again.weight, last.weight)
    assert torch.equal(latent, model.latent) and torch.equal(first.weight, model.head[1].weight)


def test_the_cell_target_is_one_pattern_for_a_move_anywhere(tiny_data, tmp_path):
    """The cell target (10x10, ``--ilpo-target cells``): how much each cell changed. A move
    from a 6-pixel cell to a 7-pixel one and one between two 6-pixel cells give the same two
    values, at the two cells and nowhere else (a fixed 4-pixel pooling cuts the cells at other
    offsets in each case); a move into the red goal cell changes the same two cells (the
    goal's by less)."""
    cfg = _config("AbcoMaze10x10-v0", tiny_data, tmp_path)
    cfg.method_options["target"] = "cells"
    cfg = resolve_config(cfg)
    method = ILPO(cfg, load_training_data(cfg), seed_everything(0))
    assert method.options.target == "cells" and method.expert_targets.shape[1] == 100
    env = gym.make("AbcoMaze10x10-v0")
    env.reset(seed=0)
    maze = env.unwrapped

    def frame(r: int, c: int) -> torch.Tensor:
        return torch.from_numpy(maze.renderer.draw_agent(maze._background.copy(), r, c))[None]

    patterns = []
    for (r, c), (r1, c1) in (((2, 2), (2, 3)), ((5, 4), (5, 5)), ((8, 9), (9, 9))):
        target = method._targets(frame(r, c), frame(r1, c1)).reshape(10, 10)
        assert (target > 0).nonzero().tolist() == sorted([[r, c], [r1, c1]])
        patterns.append(sorted([float(target[r, c]), float(target[r1, c1])]))
    env.close()
    assert patterns[0] == pytest.approx(patterns[1])
    assert 0 < patterns[2][0] < patterns[0][0] and patterns[2][1] == pytest.approx(patterns[0][1])


def test_ilpo_trains_on_the_cell_target(tiny_data, tmp_path):
    cfg = _config("AbcoMaze5x5-v0", tiny_data, tmp_path)
    cfg.method_options["target"] = "cells"
    method = ILPO(resolve_config(cfg), load_training_data(resolve_config(cfg)), seed_everything(0))
    assert method.expert_targets.shape[1] == 5 * 5  # one value per cell
    assert train(cfg)["status"] == "ok"

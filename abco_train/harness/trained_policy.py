"""A trained policy from a run folder, and an animation of it acting.

:func:`load_policy` rebuilds the run's method from ``config.json`` and ``checkpoint.pt`` (on
CPU, whatever device trained it) and returns a :class:`Policy`: observations in, greedy
actions out. Its :meth:`Policy.evaluate` repeats the run's final evaluation, and gives the
numbers of ``final.json`` back exactly. :func:`record_gif` rolls it out on chosen layouts (or
reset seeds) and writes an animated GIF (``abco play``), whole or not at all, never over
anything but a regular file: it may run beside a training that writes the same folder.

A run folder may come from elsewhere: it is read defensively (regular files only, a bounded
``config.json``, a checkpoint of data only whose state must fit the run's method), and what is
wrong with it is a :class:`~abco_train.harness.run_folder.RunFolderError` in one line.

Example (a run folder made by ``abco train``)::

    policy = load_policy("runs/AbcoMaze5x5-v0-abco-s0")
    obs, _ = gymnasium.make("AbcoMaze5x5-v0").reset(seed=0)
    action = policy(obs)                  # one observation -> one int
    actions = policy(np.stack([obs] * 8))  # a batch -> (8,) actions
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from abco_train.config.envs import use_success_rule
from abco_train.config.run import ConfigError, RunConfig, env_kind
from abco_train.harness.checkpoint import load_checkpoint, load_method_state
from abco_train.harness.evaluation import final_evaluation
from abco_train.harness.run_folder import (
    CHECKPOINT,
    CONFIG,
    RunFolderError,
    check_output,
    read_json,
    write_atomic,
)
from abco_train.harness.runtime import resolve_device, seed_everything
from abco_train.harness.training_data import TrainingData, load_training_data
from abco_train.methods.base import Method
from abco_train.methods.registry import config_from_record, get_method, identity, resolve_config

__all__ = ["Policy", "load_policy", "record_gif"]


@dataclass
class Policy:
    """A trained method's greedy policy.

    Attributes:
        config: The run's resolved config.
        method: The method, restored from the checkpoint.
        data: The run's training data (the datasets are read from the cache, or generated).
        iteration: The checkpoint's iteration (the last one for a finished run).
    """

    config: RunConfig
    method: Method
    data: TrainingData
    iteration: int

    @property
    def observation_space(self) -> Any:
        """The observations the policy takes."""
        return self.data.observation_space

    def __call__(self, obs: np.ndarray) -> Any:
        """Greedy action(s): one observation -> an ``int``; a batch -> an ``(B,)`` array."""
        obs = np.asarray(obs)
        single = obs.shape == tuple(self.observation_space.shape)
        actions = self.act(obs[None] if single else obs)
        return int(actions[0]) if single else actions

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions for a batch of observations."""
        return np.asarray(self.method.act(obs)).reshape(-1)

    def evaluate(self) -> dict[str, Any]:
        """The run's final evaluation again (same episodes, same seeds; no plots)."""
        cfg = self.config.replace(plots=False)
        use_success_rule(cfg.env, cfg.success)  # the run's --success (an env of the user's)
        return final_evaluation(cfg, self.data, self.method, [], Path(cfg.run_dir or "."))


def load_policy(run_dir: str | os.PathLike[str], *, device: str = "cpu", quiet: bool = True
                ) -> Policy:  # fmt: skip
    """The trained policy of a run folder (on CPU unless asked, wherever it trained).

    Args:
        run_dir: A folder written by ``abco train`` (or a cell of ``abco bench``).
        device: Where the policy acts: ``cpu``, ``cuda`` or ``auto``.
        quiet: No progress bars while the datasets are read.

    Raises:
        RunFolderError: No run there, or its files are damaged (or not abco's): a config
            abco cannot read, a checkpoint that is no data, of another iteration count or
            whose state does not fit the run's method.
        ConfigError: The run's method is unknown (a plugin's, without its ``--plugin``).
    """
    run_dir = Path(run_dir)
    config, checkpoint = run_dir / CONFIG, run_dir / CHECKPOINT
    if not os.path.lexists(config) or not os.path.lexists(checkpoint):
        raise RunFolderError(f"{run_dir} holds no trained run ({CONFIG} and {CHECKPOINT})")
    record = read_json(config)
    try:
        if not isinstance(record, dict):
            raise TypeError(f"a JSON {type(record).__name__}, not an object")
        cfg = resolve_config(config_from_record(record))
    except (ConfigError, TypeError, ValueError) as exc:
        raise RunFolderError(f"{config} holds no config abco can read: {exc}") from None
    cfg = cfg.replace(run_dir=str(run_dir), quiet=quiet, device=resolve_device(device))
    state = load_checkpoint(checkpoint)
    if state is None:
        raise RunFolderError(f"{checkpoint} vanished while it was read")
    if identity(state["config"]) != identity(asdict(cfg)):
        raise RunFolderError(f"{config} is not the config of {checkpoint}'s run; the folder "
                             "was changed since it was written")  # fmt: skip
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    data = load_training_data(cfg)
    method = get_method(cfg.method)(cfg, data, rng)
    iteration = load_method_state(method, state, checkpoint)
    return Policy(cfg, method, data, iteration)


def _upscale(frame: np.ndarray, min_side: int = 256) -> np.ndarray:
    k = max(1, -(-min_side // min(frame.shape[:2])))
    return np.repeat(np.repeat(frame, k, axis=0), k, axis=1)


def record_gif(
    policy: Policy,
    path: str | os.PathLike[str],
    episodes: Sequence[int] = (0,),
    *,
    split: str = "train",
    max_steps: int = 200,
    fps: int = 8,
    progress: bool = True,
) -> Path:
    """Roll ``policy`` out and write the episodes, one after another, as an animated GIF.

    Args:
        policy: From :func:`load_policy`.
        path: The ``.gif`` to write.
        episodes: Mazes: layout indices of ``split``; classic control: reset seeds.
        split: Maze split, ``train`` or ``test``.
        max_steps: Cap on each episode's length.
        fps: Frames per second.
        progress: A progress bar over the episodes.

    Returns:
        The path written.

    Raises:
        RunFolderError: ``path`` is not a new path or a regular file (left untouched).
        OSError: It cannot be written (a full disk, a read-only folder; no file is left).
    """
    import gymnasium as gym
    from PIL import Image

    from abco_data.progress import progress_bar

    check_output(path)  # before the rollouts
    cfg, maze = policy.config, env_kind(policy.config.env) == "maze"
    kwargs = {**policy.data.env_kwargs, **({"split": split} if maze else {})}
    env = gym.make(cfg.env, render_mode=None if maze else "rgb_array", **kwargs)
    frames: list[np.ndarray] = []
    for episode in progress_bar(list(episodes), desc="episodes", disable=not progress, unit="ep"):
        options = {"layout_index": int(episode), "start": (0, 0)} if maze else None
        obs, _ = env.reset(seed=int(episode), options=options)
        # gymnasium types render() by render mode; "rgb_array" gives one frame, an array
        shot = (lambda o: o) if maze else (lambda o: cast(np.ndarray, env.render()))
        frames.append(_upscale(shot(obs)))
        for _ in range(max_steps):
            obs, _, terminated, truncated, _ = env.step(policy(obs))
            frames.append(_upscale(shot(obs)))
            if terminated or truncated:
                break
        frames += [frames[-1]] * max(1, fps // 2)  # a short pause between episodes
    env.close()
    images = [Image.fromarray(f) for f in frames]
    return write_atomic(path, lambda tmp: images[0].save(
        tmp, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps),
        loop=0))  # fmt: skip

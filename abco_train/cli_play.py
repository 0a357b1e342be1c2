"""``abco play``: roll a trained policy out and write an animated GIF.

Its options are bounded (:mod:`abco_train.config.limits`: episodes, steps, frames per second
and the frames they make in all, every one held in memory until the GIF is written) and
checked, with the layouts of a maze split and pygame for classic control, before any rollout.
Frames are drawn off-screen: SDL is given its dummy drivers unless the environment sets others.
"""

from __future__ import annotations

import argparse
import contextlib
import os

from abco_train.config.fields import ConfigError, count
from abco_train.config.limits import (
    MAX_PLAY_EPISODES,
    MAX_PLAY_FPS,
    MAX_PLAY_FRAMES,
    MAX_PLAY_STEPS,
    MAX_SEED,
)

__all__ = ["add_play_options", "play", "play_episodes", "check_playable"]

def play_episodes(args: argparse.Namespace) -> list[int]:
    """``--episodes``, their number and the frames they make checked before any list is built.

    Raises:
        ConfigError: Too many episodes or frames, or a number past a seed's range.
    """
    from abco_train.bench.grid import parse_seeds

    asked = 0
    for part in args.episodes.split(","):
        first, dash, last = part.strip().partition("-")
        with contextlib.suppress(ValueError):  # a malformed part: parse_seeds names it
            asked += max(0, int(last) - int(first) + 1) if dash else 1
    if asked > MAX_PLAY_EPISODES:
        raise ConfigError(f"--episodes {args.episodes} asks for {asked:,} episodes; a GIF holds "
                          f"at most {MAX_PLAY_EPISODES:,}")  # fmt: skip
    episodes = parse_seeds(args.episodes)
    frames = len(episodes) * (args.max_steps + 1 + max(1, args.fps // 2))
    if frames > MAX_PLAY_FRAMES:
        raise ConfigError(f"--episodes {args.episodes} with --max-steps {args.max_steps} may make "
                          f"{frames:,} frames, more than the {MAX_PLAY_FRAMES:,} a GIF holds in "
                          "memory; play fewer episodes or lower --max-steps")  # fmt: skip
    if max(episodes) > MAX_SEED:
        raise ConfigError(f"--episodes must be <= {MAX_SEED:,}, got {max(episodes)}")
    return episodes


def check_playable(env_id: str, episodes: list[int], split: str) -> None:
    """Refuse, before any rollout, maze layouts past the split, classic control without
    pygame (it draws the frames) and an env that declares no ``rgb_array`` rendering.

    Raises:
        ConfigError: A layout index out of range, pygame missing, or no frames to draw.
    """
    import importlib.util

    import abco_envs

    if abco_envs.is_maze(abco_envs.env_name(env_id)):
        size = len(abco_envs.layout_pool(abco_envs.maze_size(env_id)).split(split))
        if max(episodes) >= size:
            raise ConfigError(f"--episodes: the {split} split of {env_id} has layouts 0-"
                              f"{size - 1}, got {max(episodes)}")  # fmt: skip
        return
    if env_id in abco_envs.CLASSIC_IDS and importlib.util.find_spec("pygame") is None:
        raise ConfigError(f"abco play draws {env_id} with pygame, which is not installed: "
                          'pip install "abco[human]"')  # fmt: skip
    modes = _render_modes(env_id)
    if "rgb_array" not in modes:
        raise ConfigError(f"abco play needs frames from {env_id}, which does not render "
                          f"'rgb_array' (its render modes: {', '.join(modes) or 'none'})")


def _render_modes(env_id: str) -> list[str]:
    """The render modes an env declares (``metadata["render_modes"]``; none: an empty list)."""
    import gymnasium as gym

    try:
        env = gym.make(env_id)
    except (gym.error.Error, ImportError, TypeError, ValueError) as exc:
        raise ConfigError(f"abco play cannot make {env_id}: {exc}") from None
    try:
        modes = env.metadata.get("render_modes") or []
        return [str(m) for m in modes] if isinstance(modes, (list, tuple)) else []
    finally:
        env.close()


def play(args: argparse.Namespace) -> int:
    """Run ``abco play`` (its options from :func:`add_play_options`); print the GIF's path.

    Raises:
        ConfigError: A bound, a layout past the split, or pygame missing (before any rollout).
    """
    # Frames are drawn off-screen: SDL needs no display (nor prints about a missing one).
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    from abco_train.harness.trained_policy import load_policy, record_gif
    from abco_train.methods.registry import load_plugins

    out = args.out or str(args.run_dir).rstrip("/") + f"/play_{args.split}.gif"
    if not out.lower().endswith(".gif"):
        raise ConfigError(f"--out must name a .gif file, got {out}")
    episodes = play_episodes(args)
    load_plugins(args.plugin)  # a run of a plugin's method
    policy = load_policy(args.run_dir, quiet=args.quiet)
    check_playable(policy.config.env, episodes, args.split)
    path = record_gif(policy, out, episodes, split=args.split, max_steps=args.max_steps,
                      fps=args.fps, progress=not args.quiet)  # fmt: skip
    print(f"animation: {path}")
    return 0


def add_play_options(parser: argparse.ArgumentParser) -> None:
    """Add ``abco play``'s arguments and options to ``parser``."""
    parser.add_argument("run_dir", help="a run folder written by abco train")
    parser.add_argument("--episodes", default="0-3",
                        help="mazes: layout indices of the split; classic control: reset seeds"
                        f" (e.g. 0-3 or 0,5; default 0-3); at most {MAX_PLAY_EPISODES:,} "
                        f"episodes and {MAX_PLAY_FRAMES:,} frames (episodes x (max steps + 1 + "
                        "fps/2)), held in memory until the GIF is written")  # fmt: skip
    parser.add_argument("--split", choices=("train", "test"), default="train",
                        help="maze split (default train)")  # fmt: skip
    parser.add_argument("--out", default=None, help="GIF to write (default RUN_DIR/play_SPLIT.gif)")
    parser.add_argument("--max-steps", type=count(MAX_PLAY_STEPS), default=200,
                        help=f"cap on each episode's length, at most {MAX_PLAY_STEPS:,} "
                        "(default 200)")  # fmt: skip
    parser.add_argument("--fps", type=count(MAX_PLAY_FPS), default=8,
                        help=f"frames per second, at most {MAX_PLAY_FPS} (default 8)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")

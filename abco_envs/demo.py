"""Demo: build a maze, let the shortest-path expert walk it, and save a PNG of its path.

Run ``python -m abco_envs.demo --env AbcoMaze10x10-v0 --out maze_demo.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import abco_envs  # noqa: F401  (registers the ids)
from abco_envs.experts import MazeExpert, record_episode
from abco_envs.maze.env import MazeEnv, maze_cells


def expert_path_image(env_id: str, seed: int, image_size: int) -> tuple[np.ndarray, dict]:
    """Roll out the expert on the layout ``reset(seed=seed)`` draws; draw its path on the maze."""
    env = gym.make(env_id, image_size=image_size)
    episode = record_episode(env, MazeExpert(seed=seed), seed=seed)
    maze, positions = env.unwrapped, episode.positions
    if not isinstance(maze, MazeEnv) or positions is None:
        raise ValueError(f"{env_id} is not an abco maze")
    image = maze.renderer.background(maze_cells(env))
    maze.renderer.draw_path(image, positions)
    maze.renderer.draw_agent(image, *positions[-1])
    summary = {
        "env": env_id,
        "layout_id": maze.layout_id,
        "moves": episode.length,
        "return": round(episode.episode_return, 4),
        "reached_goal": bool(episode.terminations[-1]),
    }
    return image, summary


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--env", default="AbcoMaze10x10-v0", choices=abco_envs.MAZE_IDS)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--image-size", type=int, default=256)
    parser.add_argument("--out", type=Path, default=Path("maze_demo.png"))
    args = parser.parse_args(argv)
    image, summary = expert_path_image(args.env, args.seed, args.image_size)
    import matplotlib.pyplot as plt  # only the demo writes PNGs

    args.out.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(args.out, image)
    print(" ".join(f"{k}={v}" for k, v in summary.items()), f"png={args.out}")


if __name__ == "__main__":
    main()

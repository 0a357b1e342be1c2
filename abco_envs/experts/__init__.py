"""Expert-demo generators: the maze's shortest-path expert, the classic-control controllers and
LunarLander's heuristic lander, the random policy of pre-demonstrations, and an episode
recorder."""

from abco_envs.experts.classic import CONTROLLERS, controller_for
from abco_envs.experts.maze import MazeExpert
from abco_envs.experts.random_policy import RandomPolicy
from abco_envs.experts.rollout import EpisodeRecord, Policy, record_episode
from abco_envs.ids import MAZE_IDS, env_name


def expert_policy(env_id: str, seed: int | None = None) -> Policy:
    """The expert of any of the seven envs as a ``policy(obs, info) -> action``.

    Mazes get a :class:`MazeExpert` (ties broken by ``seed``); the other ids get their
    deterministic controller (``seed`` unused; LunarLander-v3: Gymnasium's heuristic).

    Raises:
        UnknownEnvError: ``env_id`` has no expert (a ``ValueError``).
        MissingDependencyError: The env needs a package that is not installed (LunarLander:
            Box2D); the message names the abco extra to install.
    """
    if env_name(env_id) in MAZE_IDS:
        return MazeExpert(seed=seed)
    controller = controller_for(env_id)
    return lambda obs, info: controller(obs)


__all__ = [
    "CONTROLLERS",
    "EpisodeRecord",
    "MazeExpert",
    "Policy",
    "RandomPolicy",
    "controller_for",
    "expert_policy",
    "record_episode",
]

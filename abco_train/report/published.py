"""The numbers the papers published, as data.

Monteiro, Gavenski, Granada, Meneguzzi, Barros, "Augmented Behavioral Cloning from
Observation", IJCNN 2020 (arXiv:2004.13529): Table 1 (tab:results_maze) and Table 2
(tab:ablation), (P, AER) per cell, copied as printed.

Gavenski, Monteiro, Granada, Meneguzzi, Barros, "Imitating Unknown Policies via Exploration",
BMVC 2020: the AER of IUPE and of ILPO (Edwards et al., ICML 2019) on the same six
environments, as the IUPE authors report them (:data:`PUBLISHED_AER`). GAIfO has none.
"""

from __future__ import annotations

__all__ = ["PAPER_TABLE1", "PAPER_TABLE2", "PUBLISHED_AER", "published"]

PAPER_TABLE1: dict[str, dict[str, tuple[float, float]]] = {
    "bc": {"CartPole-v1": (1.000, 500.0), "Acrobot-v1": (1.071, -83.590),
           "MountainCar-v0": (1.560, -117.720), "AbcoMaze3x3-v0": (-1.207, 0.180),
           "AbcoMaze5x5-v0": (-0.921, -0.507), "AbcoMaze10x10-v0": (-0.470, -1.000)},
    "bco-alpha": {"CartPole-v1": (1.000, 500.0), "Acrobot-v1": (0.980, -117.600),
                  "MountainCar-v0": (0.948, -150.00), "AbcoMaze3x3-v0": (0.883, 0.927),
                  "AbcoMaze5x5-v0": (-0.112, 0.104), "AbcoMaze10x10-v0": (-0.416, -0.941)},
    "abco": {"CartPole-v1": (1.000, 500.0), "Acrobot-v1": (1.086, -77.900),
             "MountainCar-v0": (1.289, -132.30), "AbcoMaze3x3-v0": (1.159, 0.908),
             "AbcoMaze5x5-v0": (0.960, 0.932), "AbcoMaze10x10-v0": (0.860, 0.784)},
}  # fmt: skip
# Table 2's BCO AER (-0.941) differs from Table 1's BCO on the 5x5 maze (0.104) in the paper.
PAPER_TABLE2: dict[str, tuple[float, float]] = {
    "bco-alpha": (-0.112, -0.941), "attention": (-0.415, -0.940),
    "sampling-partial": (0.717, 0.716), "sampling-whole": (0.628, 0.676),
    "abco": (0.960, 0.932), "abco-whole": (0.759, 0.755),
}  # fmt: skip
#: AER of ILPO and IUPE as the IUPE authors report them (BMVC 2020); no P was published.
PUBLISHED_AER: dict[str, dict[str, float]] = {
    "ilpo": {"CartPole-v1": 500.0, "Acrobot-v1": -85.3, "MountainCar-v0": -167.0,
             "AbcoMaze3x3-v0": -0.026, "AbcoMaze5x5-v0": -0.059, "AbcoMaze10x10-v0": -0.020},
    "iupe": {"CartPole-v1": 500.0, "Acrobot-v1": -78.1, "MountainCar-v0": -130.7,
             "AbcoMaze3x3-v0": 0.927, "AbcoMaze5x5-v0": 0.971, "AbcoMaze10x10-v0": 0.981},
}  # fmt: skip


def published(method: str, env: str) -> tuple[float | None, float] | None:
    """The published ``(P, AER)`` of a Table 1 cell (P ``None`` where only AER was published).

    Example:
        >>> published("abco", "AbcoMaze5x5-v0"), published("iupe", "Acrobot-v1")
        ((0.96, 0.932), (None, -78.1))
        >>> published("gaifo", "CartPole-v1") is None
        True
    """
    if env in PAPER_TABLE1.get(method, {}):
        return PAPER_TABLE1[method][env]
    if env in PUBLISHED_AER.get(method, {}):
        return None, PUBLISHED_AER[method][env]
    return None

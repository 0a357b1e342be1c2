"""The numbers the ABCO paper published, as data.

Monteiro, Gavenski, Granada, Meneguzzi, Barros, "Augmented Behavioral Cloning from
Observation", IJCNN 2020 (arXiv:2004.13529): Table 1 (tab:results_maze) and Table 2
(tab:ablation), (P, AER) per cell, copied as printed.
"""

from __future__ import annotations

__all__ = ["PAPER_TABLE1", "PAPER_TABLE2"]

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

"""Small creation parameters for fast dataset tests (shared by tests/data/test_*.py)."""

from __future__ import annotations

from pathlib import Path

import abco_data

MAZE_EXPERT_SMALL = {"layouts": 2, "solutions_per_layout": 2, "reference_episodes": 5}
MAZE_PRE_SMALL = {"layouts": 2, "episodes_per_layout": 4, "max_steps": 6,
                  "reference_episodes": 5}
CLASSIC_EXPERT_SMALL = {"episodes": 2, "reference_episodes": 2, "reference_expert_episodes": 1}
CLASSIC_PRE_SMALL = {"transitions": 300, "reference_episodes": 2,
                     "reference_expert_episodes": 1}


def small_overrides(dataset_id: str) -> dict:
    """Overrides that make ``dataset_id`` generate in well under a second."""
    s = abco_data.spec(dataset_id)
    if s.is_maze:
        return dict(MAZE_EXPERT_SMALL if s.kind == "expert" else MAZE_PRE_SMALL)
    return dict(CLASSIC_EXPERT_SMALL if s.kind == "expert" else CLASSIC_PRE_SMALL)


def make_small(dataset_id: str, directory: Path, name: str | None = None, **extra) -> Path:
    """Generate a small version of ``dataset_id`` into ``directory``."""
    path = Path(directory) / (name or abco_data.spec(dataset_id).filename)
    return abco_data.generate(dataset_id, path, progress=False,
                              **{**small_overrides(dataset_id), **extra})

"""The abco datasets: their ids and the parameters that create each one.

Ids read ``abco/{name}-{kind}-v0``: ``name`` is one of the seven environments, ``kind`` is
``expert`` or ``pre`` (pre-demonstrations), and the trailing version changes whenever the
bytes of a dataset would. The six environments of the paper's Table 1 come first;
LunarLander-v3's two (:data:`ADDED_ENVS`) come after every other family, so that no older
dataset's seed (and bytes) changed when they were added. Two families more, for the mazes:
``abco/{maze}-pre-start-v0`` (the authors' start-cell pre-demonstrations) and, for 5x5 and
10x10, ``abco/{maze}-procedural-{kind}-v0``: 10,000 layouts of the procedural split
(:mod:`abco_envs.maze.procedural`), disjoint from the pool's train and test splits. One for
Acrobot: ``abco/acrobot-pre-held-v0``, random actions each held for several steps. The
classic-control expert datasets have a version 1 (``abco/cartpole-expert-v1``, ...): the same
episodes with reference returns over more episodes; :func:`dataset_id` names it.
:func:`check_layout_count` checks a number of layouts asked of a maze dataset.

Example:
    >>> dataset_id("AbcoMaze5x5-v0", "expert"), dataset_id("CartPole-v1", "expert")
    ('abco/maze5x5-expert-v0', 'abco/cartpole-expert-v1')
    >>> s = spec("abco/cartpole-pre-v0")
    >>> s.env_id, s.kind, s.params["transitions"]
    ('CartPole-v1', 'pre_demonstrations', 50000)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

import abco_envs
from abco_data.errors import UnknownDatasetError
from abco_data.generation.bounds import check_params
from abco_envs.maze.procedural import PROCEDURAL_SPLIT_SIZE

__all__ = ["DatasetSpec", "DATASET_IDS", "ENV_NAMES", "ACTION_COUNTS", "PROCEDURAL_ENVS",
           "DATASET_SPLITS", "HELD_ENVS", "TABLE1_ENVS", "ADDED_ENVS", "dataset_id",
           "procedural_dataset_id",
           "start_cell_dataset_id",
           "held_dataset_id", "spec", "is_maze", "check_layout_count", "CLASSIC_EXPERT_VERSION"]

#: Short dataset name of each environment id.
ENV_NAMES = {
    "AbcoMaze3x3-v0": "maze3x3",
    "AbcoMaze5x5-v0": "maze5x5",
    "AbcoMaze10x10-v0": "maze10x10",
    "CartPole-v1": "cartpole",
    "Acrobot-v1": "acrobot",
    "MountainCar-v0": "mountaincar",
    "LunarLander-v3": "lunarlander",
}
#: The environments of the paper's Table 1, whose expert and pre-demonstration datasets come
#: first (their seeds follow this order).
TABLE1_ENVS = ("AbcoMaze3x3-v0", "AbcoMaze5x5-v0", "AbcoMaze10x10-v0", "CartPole-v1",
               "Acrobot-v1", "MountainCar-v0")
#: Environments added since: the same two datasets each, made as the classic-control ones
#: are, after every other family (ids and seeds).
ADDED_ENVS = ("LunarLander-v3",)
#: ``n`` of each environment's ``Discrete(n)`` action space (a file claiming another is bad).
ACTION_COUNTS = {"AbcoMaze3x3-v0": 4, "AbcoMaze5x5-v0": 4, "AbcoMaze10x10-v0": 4,
                 "CartPole-v1": 2, "Acrobot-v1": 3, "MountainCar-v0": 3, "LunarLander-v3": 4}
_KIND_SUFFIX = {"expert": "expert", "pre_demonstrations": "pre"}
VERSION = 0

#: Parameters shared by every dataset of a family; ``seed`` is set per dataset below.
_MAZE_EXPERT = {
    "layouts": 100,  # the first k layouts of the train split (all 100 by default)
    "solutions_per_layout": 10,  # expert episodes per layout, each with its own tie-break seed
    "image_size": 64,
    "reference_episodes": 100,  # random episodes per layout for the random reference return
}
_MAZE_PRE = {
    "layouts": 100,
    "episodes_per_layout": 20,
    "max_steps": 10,  # short random walks from a random start cell (never the goal)
    "drop_wall_hits": False,  # True drops moves into a wall (s' == s) from the data
    "image_size": 64,
    "reference_episodes": 100,
}
#: The authors' pre-demonstrations (their ``--no_hit`` agent): random walks from the start cell,
#: as an agent that resets the env would, with moves into walls dropped. A parameter of these
#: datasets only, so the older datasets' stored parameters (and bytes) stay as they were.
_MAZE_PRE_START = {**_MAZE_PRE, "episodes_per_layout": 40, "drop_wall_hits": True,
                   "from_start_cell": True}
#: The procedural datasets: every layout of the procedural split, each layout's episodes
#: together and layouts in split order, so the first ``K`` layouts are a prefix of the file
#: (``Dataset.first_layouts``). One shortest path per layout: a layout's expert paths share
#: most of their cells, and another layout teaches more than another path through the same
#: one. Two random walks of at most 10 steps per layout (the standard ``-pre-`` walks, wall
#: hits kept): about 19 transitions a layout, so the first 1,000 layouts hold as many as the
#: standard 100-layout ``-pre-`` dataset, and all 10,000 about as many as the expert file;
#: a reader that decodes whole files needs 12 KiB a 64x64 frame, which 20 walks a layout
#: would take past 25 GB on 10x10 (the trainer draws frames per minibatch instead).
_MAZE_PROCEDURAL_EXPERT = {**_MAZE_EXPERT, "layouts": PROCEDURAL_SPLIT_SIZE,
                           "solutions_per_layout": 1, "split": "procedural"}
_MAZE_PROCEDURAL_PRE = {**_MAZE_PRE, "layouts": PROCEDURAL_SPLIT_SIZE, "episodes_per_layout": 2,
                        "split": "procedural"}
#: The maze sizes with procedural datasets (the issue's two; 3x3 has no procedural split).
PROCEDURAL_ENVS = ("AbcoMaze5x5-v0", "AbcoMaze10x10-v0")
#: Layout splits a dataset may be made from (``split`` creation parameter; absent: train).
#: Never ``test`` or ``fresh``: those layouts stay out of every dataset.
DATASET_SPLITS = ("train", "procedural")
_CLASSIC_EXPERT = {"episodes": 50, "reference_episodes": 100, "reference_expert_episodes": 20}
_CLASSIC_PRE = {"transitions": 50_000, "reference_episodes": 100,
                "reference_expert_episodes": 20}
#: Held-action pre-demonstrations: each uniform random action is repeated for ``hold`` steps
#: (an int, or ``[lo, hi]``: a length drawn per action, see ``RandomPolicy``). One-step
#: random torques leave Acrobot near rest, while its expert swings fast: an IDM trained on
#: them labels ~10% of the expert's pairs "zero torque". Held torques pump energy as the
#: expert does (docs/notes/acrobot-alpha-and-earlier-studies.md). A parameter of these
#: datasets only, so the ``-pre-`` datasets' stored parameters (and bytes) stay as they were.
_CLASSIC_PRE_HELD = {**_CLASSIC_PRE, "hold": 4}
#: The environments with a held-action dataset ``abco/{name}-pre-held-v0``.
HELD_ENVS = ("Acrobot-v1",)
#: The classic-control expert datasets' version 1: v0's episodes (the same seed, the same
#: bytes), their reference returns over 2,000 random and 1,000 expert episodes instead of 100
#: and 20, so that each reference's standard error is under 0.01 of the score's scale
#: (LunarLander's returns spread most: 113 for random actions, 111 for its expert, over a scale
#: of 423; docs/notes/fair-fight.md). The default of every run; v0 stays for the records that
#: used it.
CLASSIC_EXPERT_VERSION = 1
_CLASSIC_EXPERT_V1 = {**_CLASSIC_EXPERT, "reference_episodes": 2000,
                      "reference_expert_episodes": 1000}


@dataclass(frozen=True)
class DatasetSpec:
    """How one dataset is made.

    Attributes:
        id: The dataset id, e.g. ``"abco/maze5x5-expert-v0"``.
        env_id: The Gymnasium id of its environment.
        kind: ``"expert"`` or ``"pre_demonstrations"``.
        params: Creation parameters (read-only mapping), ``seed`` included.
    """

    id: str
    env_id: str
    kind: str
    params: Mapping[str, Any]

    @property
    def is_maze(self) -> bool:
        """Whether the environment is one of the abco mazes."""
        return is_maze(self.env_id)

    @property
    def filename(self) -> str:
        """File name of the dataset, e.g. ``"maze5x5-expert-v0.hdf5"``."""
        return self.id.split("/", 1)[1] + ".hdf5"

    def with_overrides(self, **overrides: Any) -> DatasetSpec:
        """A copy whose parameters are updated by ``overrides`` (only known keys), each
        checked against its bounds (:mod:`abco_data.generation.bounds`) before anything is made.

        Raises:
            TypeError: An override that this dataset has no parameter for, or one of
                ``split`` (a dataset's layout split is part of its id).
            InvalidParameterError: A value of the wrong type or beyond its bound (also a
                ``ValueError``).
        """
        unknown = sorted(set(overrides) - set(self.params))
        if unknown:
            raise TypeError(
                f"{self.id} has no parameter(s) {', '.join(unknown)};"
                f" known: {', '.join(sorted(self.params))}")
        if "split" in overrides:
            raise TypeError(f"{self.id}: parameter split cannot be overridden (the layout split"
                            " of a dataset is part of its id)")
        params = {**self.params, **overrides}
        check_params(self.id, self.env_id, self.kind, params)
        return DatasetSpec(self.id, self.env_id, self.kind, MappingProxyType(params))


def is_maze(env_id: str) -> bool:
    """Whether ``env_id`` is an abco maze id."""
    return abco_envs.is_maze(env_id)


def _normalise_kind(kind: str) -> str:
    aliases = {"expert": "expert", "pre": "pre_demonstrations",
               "pre_demonstrations": "pre_demonstrations", "pre-demonstrations":
               "pre_demonstrations"}
    if kind not in aliases:
        raise ValueError(f"unknown dataset kind {kind!r}; expected 'expert' or"
                         " 'pre_demonstrations'")
    return aliases[kind]


def dataset_id(env_id: str, kind: str) -> str:
    """The id of the ``kind`` dataset of ``env_id`` (``kind``: expert | pre_demonstrations).

    Raises:
        UnknownDatasetError: No dataset exists for ``env_id``.
        ValueError: Unknown ``kind``.
    """
    name = ENV_NAMES.get(abco_envs.env_name(env_id))
    if name is None:
        raise UnknownDatasetError(
            f"no abco dataset for env {env_id!r}; envs with datasets: {', '.join(ENV_NAMES)}")
    kind = _normalise_kind(kind)
    version = VERSION if is_maze(env_id) or kind != "expert" else CLASSIC_EXPERT_VERSION
    return f"abco/{name}-{_KIND_SUFFIX[kind]}-v{version}"


def _variant_id(env_id: str, envs: tuple[str, ...], what: str, suffix: str) -> str:
    """``abco/{name}-{suffix}-v{VERSION}`` of a dataset variant that only ``envs`` have.

    Raises:
        UnknownDatasetError: ``env_id`` is not one of ``envs`` (the message names them).
    """
    name = abco_envs.env_name(env_id)
    if name not in envs:
        raise UnknownDatasetError(f"no {what} abco dataset for env {env_id!r}; envs with one: "
                                  f"{', '.join(envs)}")  # fmt: skip
    return f"abco/{ENV_NAMES[name]}-{suffix}-v{VERSION}"


def procedural_dataset_id(env_id: str, kind: str) -> str:
    """The id of the procedural ``kind`` dataset of ``env_id`` (mazes 5x5 and 10x10).

    Example:
        >>> procedural_dataset_id("AbcoMaze10x10-v0", "pre")
        'abco/maze10x10-procedural-pre-v0'

    Raises:
        UnknownDatasetError: No procedural dataset exists for ``env_id``.
        ValueError: Unknown ``kind``.
    """
    suffix = _KIND_SUFFIX[_normalise_kind(kind)]
    return _variant_id(env_id, PROCEDURAL_ENVS, "procedural", f"procedural-{suffix}")


def start_cell_dataset_id(env_id: str) -> str:
    """The id of a maze's start-cell pre-demonstrations without wall hits (the authors' regime).

    Example:
        >>> start_cell_dataset_id("AbcoMaze5x5-v0")
        'abco/maze5x5-pre-start-v0'

    Raises:
        UnknownDatasetError: ``env_id`` is not an abco maze.
    """
    return _variant_id(env_id, abco_envs.MAZE_IDS, "start-cell", "pre-start")


def held_dataset_id(env_id: str) -> str:
    """The id of the held-action pre-demonstrations of ``env_id`` (Acrobot only).

    Example:
        >>> held_dataset_id("Acrobot-v1")
        'abco/acrobot-pre-held-v0'

    Raises:
        UnknownDatasetError: No held-action dataset exists for ``env_id``.
    """
    return _variant_id(env_id, HELD_ENVS, "held-action", "pre-held")


def _standard_pair(env_id: str, first: int) -> dict[str, DatasetSpec]:
    """The expert and pre-demonstration specs of ``env_id``, seeded ``first`` and
    ``first + 1`` millions."""
    specs = {}
    for j, kind in enumerate(("expert", "pre_demonstrations")):
        if is_maze(env_id):
            base = _MAZE_EXPERT if kind == "expert" else _MAZE_PRE
        else:
            base = _CLASSIC_EXPERT if kind == "expert" else _CLASSIC_PRE
        # Disjoint seed ranges: 1,000,000 apart per dataset, so episode seeds never meet.
        params = {**base, "seed": (first + j) * 1_000_000}
        ds_id = f"abco/{ENV_NAMES[env_id]}-{_KIND_SUFFIX[kind]}-v{VERSION}"
        specs[ds_id] = DatasetSpec(ds_id, env_id, kind, MappingProxyType(params))
    return specs


def _classic_expert_v1(v0: dict[str, DatasetSpec]) -> dict[str, DatasetSpec]:
    """The classic-control expert datasets' version 1, each with its v0's seed."""
    specs = {}
    for env_id in (*TABLE1_ENVS, *ADDED_ENVS):
        if not is_maze(env_id):
            seed = v0[f"abco/{ENV_NAMES[env_id]}-expert-v{VERSION}"].params["seed"]
            ds_id = dataset_id(env_id, "expert")
            specs[ds_id] = DatasetSpec(ds_id, env_id, "expert", MappingProxyType(
                {**_CLASSIC_EXPERT_V1, "seed": seed}))  # fmt: skip
    return specs


def _build() -> dict[str, DatasetSpec]:
    specs = {}
    for i, env_id in enumerate(TABLE1_ENVS):
        specs.update(_standard_pair(env_id, 2 * i + 1))
    for k, env_id in enumerate(e for e in TABLE1_ENVS if is_maze(e)):
        params = {**_MAZE_PRE_START, "seed": (2 * len(TABLE1_ENVS) + k + 1) * 1_000_000}
        ds_id = start_cell_dataset_id(env_id)
        specs[ds_id] = DatasetSpec(ds_id, env_id, "pre_demonstrations", MappingProxyType(params))
    first = 2 * len(TABLE1_ENVS) + 3 + 1  # after the three start-cell datasets
    for k, (env_id, kind) in enumerate((e, kind) for e in PROCEDURAL_ENVS
                                       for kind in ("expert", "pre_demonstrations")):
        base = _MAZE_PROCEDURAL_EXPERT if kind == "expert" else _MAZE_PROCEDURAL_PRE
        params = {**base, "seed": (first + k) * 1_000_000}
        ds_id = procedural_dataset_id(env_id, kind)
        specs[ds_id] = DatasetSpec(ds_id, env_id, kind, MappingProxyType(params))
    first += 2 * len(PROCEDURAL_ENVS)  # after the procedural datasets
    for k, env_id in enumerate(HELD_ENVS):
        params = {**_CLASSIC_PRE_HELD, "seed": (first + k) * 1_000_000}
        ds_id = held_dataset_id(env_id)
        specs[ds_id] = DatasetSpec(ds_id, env_id, "pre_demonstrations", MappingProxyType(params))
    first += len(HELD_ENVS)  # after the held-action datasets
    for k, env_id in enumerate(ADDED_ENVS):
        specs.update(_standard_pair(env_id, first + 2 * k))
    specs.update(_classic_expert_v1(specs))
    return specs


_SPECS = _build()
#: The dataset ids: the twelve of Table 1 (mazes first, expert before pre-demonstrations),
#: then the mazes' start-cell pre-demonstrations of the authors' regime, then the procedural
#: datasets (5x5 expert and pre, 10x10 expert and pre), then the held-action ones (Acrobot),
#: then the expert and pre-demonstrations of each added environment (LunarLander), then the
#: classic-control expert datasets' version 1 (:data:`CLASSIC_EXPERT_VERSION`).
DATASET_IDS: tuple[str, ...] = tuple(_SPECS)


def spec(dataset_id: str) -> DatasetSpec:
    """The :class:`DatasetSpec` of ``dataset_id``.

    Raises:
        UnknownDatasetError: An id that is not one of :data:`DATASET_IDS` (the message lists
            them).
    """
    try:
        return _SPECS[dataset_id]
    except (KeyError, TypeError):
        raise UnknownDatasetError(
            f"unknown dataset id {dataset_id!r}; known ids: {', '.join(DATASET_IDS)}"
        ) from None


def check_layout_count(k: object, available: int, what: str, dataset_id: str) -> int:
    """``k`` as an int from 1 to ``available`` (the layouts of ``dataset_id``).

    Raises:
        ValueError: Anything else; the message starts with ``what``.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise ValueError(f"{what}: the number of layouts must be an integer from 1 to"
                         f" {available}, got {type(k).__name__}")
    if not 1 <= k <= available:
        raise ValueError(f"{what} is out of range: {dataset_id} has {available} layouts; take"
                         f" from 1 to {available}")
    return int(k)

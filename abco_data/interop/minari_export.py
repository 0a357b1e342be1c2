"""Export an abco dataset to Minari (optional extra: ``pip install abco[minari]``).

The export goes through Minari's public API (:func:`minari.create_dataset_from_buffers` with
one :class:`minari.data_collector.EpisodeBuffer` per episode), with images stored losslessly
(``jpeg_encoding=False``), so ``minari.load_dataset`` reads it as any Minari dataset. The
environment spec recorded is the one the data came from (mazes: with their ``env_kwargs``, so
``recover_environment()`` gives image observations); importing this module imports
``abco_envs``, which registers the maze ids.

Actions: pre-demonstrations export their ``actions``. Expert datasets have no training
actions, and export none: their Minari action space is the empty ``Box(0,)`` (each step's
action is an empty array). The expert's own actions, which abco keeps apart for measuring IDM
accuracy only, are in each episode's ``infos["idm_eval_actions"]``: a Minari user must not
train an imitation-from-observation method on them.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import minari
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec
from minari.data_collector import EpisodeBuffer
from minari.namespace import create_namespace, list_local_namespaces

import abco_envs  # noqa: F401  (registers the maze ids that the datasets' env specs name)
from abco_data.dataset import Dataset, open_dataset
from abco_data.format import IDM_EVAL_ACTIONS
from abco_data.format.arrays import DatasetArrays
from abco_data.format.files import atomic_target, check_target, remove_path, temporary_name

__all__ = ["export_to_minari", "NO_ACTIONS"]

#: The Minari action space of an expert export: no action at all.
NO_ACTIONS = spaces.Box(0, 0, shape=(0,), dtype=np.int64)
#: Minari reads its datasets root from this variable only.
_ROOT_ENV = "MINARI_DATASETS_PATH"


@contextmanager
def _minari_root(root: Path) -> Iterator[None]:
    """Make Minari use ``root`` as its datasets root for the block (and restore it after)."""
    before = os.environ.get(_ROOT_ENV)
    os.environ[_ROOT_ENV] = str(root)
    try:
        yield
    finally:
        if before is None:
            del os.environ[_ROOT_ENV]
        else:
            os.environ[_ROOT_ENV] = before


def _buffers(ds: Dataset, a: DatasetArrays) -> Iterator[EpisodeBuffer]:
    """One episode buffer per episode; expert episodes with no actions (see the module)."""
    expert = ds.action_column == IDM_EVAL_ACTIONS
    actions, idm_eval = (None, a.idm_eval_actions) if expert else (a.actions, None)
    for e in range(ds.num_episodes):
        o, t, n = (int(x[e]) for x in (a.episode_starts, a.episode_transition_starts,
                                       a.episode_lengths))
        steps = slice(t, t + n)
        # Minari annotates these fields as lists, but its storage takes numpy arrays as well
        # (no list of every frame): hence a plain dict of keyword arguments.
        columns: dict[str, Any] = {
            "observations": a.observations[o : o + n + 1],
            "actions": np.empty((n, 0), dtype=np.int64) if actions is None else actions[steps],
            "rewards": a.rewards[steps], "terminations": a.terminations[steps],
            "truncations": a.truncations[steps]}
        yield EpisodeBuffer(
            id=e, seed=int(a.episode_seeds[e]), **columns,
            infos=None if idm_eval is None else {IDM_EVAL_ACTIONS: idm_eval[steps]})


def _env_spec(ds: Dataset) -> EnvSpec:
    """The spec of the env the data came from, with the ``env_kwargs`` it was made with."""
    base = gym.spec(ds.env_id)
    kwargs = json.loads(ds.attrs.get("env_kwargs", "{}"))
    return dataclasses.replace(base, kwargs={**base.kwargs, **kwargs})


def _create(ds: Dataset, minari_id: str) -> None:
    """Create Minari dataset ``minari_id`` under the current Minari root."""
    expert = ds.action_column == IDM_EVAL_ACTIONS
    spec = _env_spec(ds)
    description = (
        f"abco dataset {ds.id} ({ds.kind}, abco format_version {ds.attrs['format_version']})"
        f" exported from {ds.path.name}."
        + (" No actions (expert data for imitation from observation); infos['idm_eval_actions']"
           " holds the expert's actions, for measuring IDM accuracy only, never for training."
           if expert else ""))
    with warnings.catch_warnings():
        # Minari warns about every optional field left out (permalink, e-mail): noise here.
        warnings.filterwarnings("ignore", category=UserWarning, module=r"minari\b")
        minari.create_dataset_from_buffers(
            minari_id, list(_buffers(ds, ds.load_arrays())), env=spec, eval_env=spec,
            observation_space=ds.observation_space,
            action_space=NO_ACTIONS if expert else ds.action_space,
            algorithm_name="abco expert" if expert else "uniform random policy",
            author="abco", description=description,
            ref_min_score=ds.reference.random_mean, ref_max_score=ds.reference.expert_mean,
            jpeg_encoding=False,
        )


def _datasets_root(root: str | os.PathLike[str] | None) -> Path:
    if root is not None:
        return Path(root)
    from minari.storage.datasets_root_dir import get_dataset_path

    return Path(get_dataset_path())


def export_to_minari(dataset: Dataset | str | os.PathLike[str], minari_id: str | None = None,
                     *, datasets_root: str | os.PathLike[str] | None = None,
                     overwrite: bool = False) -> Path:
    """Write ``dataset`` as a local Minari dataset; return its ``data`` folder.

    The dataset is created in a hidden folder of the datasets root, then moved into place:
    an export that fails leaves no half-written dataset.

    Args:
        dataset: An opened :class:`~abco_data.dataset.Dataset` or the path of a file.
        minari_id: Minari id; default the abco id (``abco/maze5x5-expert-v0`` is a valid one).
        datasets_root: Minari's datasets root; default Minari's own
            (``$MINARI_DATASETS_PATH`` or ``~/.minari/datasets``).
        overwrite: Replace an existing Minari dataset of that id.

    Raises:
        FileExistsError: The Minari dataset exists and ``overwrite`` is False.
        InvalidTargetError: The dataset's path in the datasets root is not a folder (a file,
            a symbolic link, a device...); checked before anything is written.

    Example:
        >>> import tempfile, os, minari, abco_data
        >>> tmp = tempfile.mkdtemp()
        >>> path = abco_data.generate("abco/maze3x3-expert-v0", os.path.join(tmp, "m.hdf5"),
        ...     progress=False, layouts=1, solutions_per_layout=2, reference_episodes=2)
        >>> _ = export_to_minari(path, datasets_root=os.path.join(tmp, "minari"))
        >>> os.environ["MINARI_DATASETS_PATH"] = os.path.join(tmp, "minari")
        >>> m = minari.load_dataset("abco/maze3x3-expert-v0")
        >>> episode = next(m.iterate_episodes())
        >>> m.action_space, episode.actions.shape[1], sorted(episode.infos)
        (Box([], [], (0,), int64), 0, ['idm_eval_actions'])
        >>> del os.environ["MINARI_DATASETS_PATH"]
    """
    ds = dataset if isinstance(dataset, Dataset) else open_dataset(dataset)
    minari_id = minari_id or ds.id
    root = _datasets_root(datasets_root)
    target = root / minari_id
    if target.exists() and not overwrite:
        raise FileExistsError(f"Minari dataset {minari_id} already exists at {target}")
    check_target(target, folder=True)
    build_root = temporary_name(root / "export", "minari")
    try:
        with _minari_root(build_root):
            _create(ds, minari_id)
        with atomic_target(target, "minari", folder=True) as tmp:
            os.replace(build_root / minari_id, tmp)
        namespace = minari_id.rpartition("/")[0]
        with _minari_root(root):
            if namespace and namespace not in list_local_namespaces():
                create_namespace(namespace)
    finally:
        remove_path(build_root)
        if not isinstance(dataset, Dataset):
            ds.close()
    return target / "data"

"""Export an abco dataset to Minari's format (optional extra: ``pip install abco[minari]``).

Minari's HDF5 storage is a folder ``<datasets root>/<namespace>/<name>-v<N>/data`` holding
``metadata.json`` (counts, serialized spaces, env spec, versions) and ``main_data.hdf5`` (one
group ``episode_<i>`` per episode with ``observations`` (T+1), ``actions``, ``rewards``,
``terminations``, ``truncations``). The export writes exactly that, with images stored
losslessly (``jpeg_encoding`` false), so ``minari.load_dataset`` reads it.

Minari requires actions. Pre-demonstrations export their ``actions``; expert datasets export
their ``idm_eval_actions`` (the expert's own actions, which abco keeps apart for measuring IDM
accuracy): a Minari user must not train an imitation-from-observation method on them.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from abco_data.dataset import Dataset, open_dataset

__all__ = ["export_to_minari"]


def _datasets_root(root: str | os.PathLike[str] | None) -> Path:
    if root is not None:
        return Path(root)
    from minari.storage.datasets_root_dir import get_dataset_path

    return Path(get_dataset_path())


def _metadata(ds: Dataset, minari_id: str, size: int) -> dict[str, Any]:
    import gymnasium as gym
    import minari
    from minari.serialization import serialize_space

    expert = ds.kind == "expert"
    return {
        "dataset_id": minari_id,
        "total_episodes": ds.num_episodes,
        "total_steps": ds.num_transitions,
        "data_format": "hdf5",
        "jpeg_encoding": False,
        "observation_space": serialize_space(ds.observation_space),
        "action_space": serialize_space(ds.action_space),
        "env_spec": gym.spec(ds.env_id).to_json(),
        "minari_version": minari.__version__,
        "algorithm_name": "abco expert" if expert else "uniform random policy",
        "author": ["abco"],
        "description": (
            f"abco dataset {ds.id} ({ds.kind}) exported from {ds.path.name}."
            + (" Actions are the expert's idm_eval_actions: for measuring IDM accuracy only,"
               " not for training imitation from observation." if expert else "")),
        "ref_max_score": ds.reference.expert_mean,
        "ref_min_score": ds.reference.random_mean,
        "dataset_size": round(size / 1e6, 1),
        "abco_format_version": int(ds.attrs["format_version"]),
    }


def export_to_minari(dataset: Dataset | str | os.PathLike[str], minari_id: str | None = None,
                     *, datasets_root: str | os.PathLike[str] | None = None,
                     overwrite: bool = False) -> Path:
    """Write ``dataset`` as a local Minari dataset; return its ``data`` folder.

    Args:
        dataset: An opened :class:`~abco_data.dataset.Dataset` or the path of a file.
        minari_id: Minari id; default the abco id (``abco/maze5x5-expert-v0`` is a valid one).
        datasets_root: Minari's datasets root; default Minari's own
            (``$MINARI_DATASETS_PATH`` or ``~/.minari/datasets``).
        overwrite: Replace an existing Minari dataset of that id.

    Raises:
        FileExistsError: The Minari dataset exists and ``overwrite`` is False.

    Example:
        >>> import tempfile, os, minari, abco_data
        >>> tmp = tempfile.mkdtemp()
        >>> path = abco_data.generate("abco/cartpole-pre-v0", os.path.join(tmp, "c.hdf5"),
        ...     progress=False, transitions=50, reference_episodes=1, reference_expert_episodes=1)
        >>> _ = export_to_minari(path, datasets_root=os.path.join(tmp, "minari"))
        >>> os.environ["MINARI_DATASETS_PATH"] = os.path.join(tmp, "minari")
        >>> minari.load_dataset("abco/cartpole-pre-v0").total_steps
        50
        >>> del os.environ["MINARI_DATASETS_PATH"]
    """
    ds = dataset if isinstance(dataset, Dataset) else open_dataset(dataset)
    minari_id = minari_id or ds.id
    target = _datasets_root(datasets_root) / minari_id
    if target.exists() and not overwrite:
        raise FileExistsError(f"Minari dataset {minari_id} already exists at {target}")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
    data = tmp / "data"
    data.mkdir(parents=True)
    try:
        a = ds.load_arrays()
        actions = a.actions if a.actions is not None else a.idm_eval_actions
        with h5py.File(data / "main_data.hdf5", "w", track_order=True) as f:
            for e in range(ds.num_episodes):
                o, t, n = (int(x[e]) for x in (a.episode_starts, a.episode_transition_starts,
                                               a.episode_lengths))
                g = f.create_group(f"episode_{e}")
                g.attrs["id"] = e
                g.attrs["seed"] = int(a.episode_seeds[e])
                g.attrs["total_steps"] = n
                obs = a.observations[o : o + n + 1]
                g.create_dataset("observations", data=obs, chunks=True,
                                 compression="gzip" if obs.ndim > 2 else None)
                g.create_dataset("actions", data=actions[t : t + n])
                for key in ("rewards", "terminations", "truncations"):
                    g.create_dataset(key, data=np.asarray(getattr(a, key)[t : t + n]))
        size = (data / "main_data.hdf5").stat().st_size
        (data / "metadata.json").write_text(json.dumps(_metadata(ds, minari_id, size)))
        if target.exists():
            shutil.rmtree(target)
        os.replace(tmp, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if not isinstance(dataset, Dataset):
            ds.close()
    namespace_file = target.parent / "namespace_metadata.json"
    if "/" in minari_id and not namespace_file.exists():
        namespace_file.write_text("{}")
    return target / "data"

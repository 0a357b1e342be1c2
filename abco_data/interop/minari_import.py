"""Importing a Minari dataset as an abco dataset (optional extra: ``pip install abco[minari]``).

:func:`import_minari` reads a Minari dataset through Minari's public API
(``minari.load_dataset``, or ``minari.MinariDataset`` on a folder, ``iterate_episodes``,
``recover_environment``) and writes it in abco's format with the writer of the user's own
datasets (:mod:`abco_data.user.writer`): by default an expert dataset of its observations,
every episode's ``T + 1``, its actions kept apart as ``idm_eval_actions`` (a dataset that
abco exported, which holds no actions, gives back the ``infos["idm_eval_actions"]`` it
carries). An episode that ends neither in a termination nor a truncation (cut short when
the data was collected) is stored as truncated; episodes without a step are left out.

Reference returns: Minari's own, ``ref_min_score`` (random) and ``ref_max_score`` (expert)
of the dataset's metadata, where it has them. A missing random reference is measured as the
built-in datasets' are, uniform random actions in the dataset's environment
(``recover_environment``) over ``reference_episodes`` episodes reset with seeds
``12345 + i``; a missing expert reference is the mean return of the dataset's own episodes
(the expert's, as recorded). The file holds a user id (:mod:`abco_data.user.ids`): one given
(``id``, then registered) or one made of the file name.

Minari files come from elsewhere: the work is bounded (at most
:data:`~abco_data.generation.bounds.MAX_TRANSITIONS` steps and
:data:`~abco_data.generation.bounds.MAX_FRAME_BYTES` of observations, counted as they are
read, whatever the metadata says) and every value is checked as a recording's are.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

import abco_envs
from abco_data.errors import (
    CorruptDatasetError,
    DatasetError,
    InvalidParameterError,
    UnknownDatasetError,
)
from abco_data.format import IDM_EVAL_ACTIONS, to_json
from abco_data.format.files import check_target
from abco_data.generation.bounds import MAX_FRAME_BYTES, MAX_TRANSITIONS, check_params
from abco_data.generation.reference import REFERENCE_SEED, ReferenceReturns
from abco_data.progress import progress_bar
from abco_data.user.datasets import register_user_dataset, user_target
from abco_data.user.writer import (
    EpisodeColumns,
    check_spaces,
    clean_observations,
    env_spec_json,
    kind_name,
    mean_return,
    write_episodes,
)

__all__ = ["import_minari", "GENERATOR", "GENERATOR_VERSION"]

logger = logging.getLogger(__name__)

#: ``generator`` and ``generator_version`` of an imported file.
GENERATOR = "abco_data.interop.minari_import"
GENERATOR_VERSION = 1
#: What Minari and h5py raise on a dataset they cannot read (Minari asserts its metadata).
_READ_ERRORS = (OSError, ValueError, KeyError, TypeError, AssertionError, IndexError)


def _open(source: str | os.PathLike[str], download: bool) -> Any:
    """The Minari dataset at folder ``source`` (or its ``data`` folder), or of id ``source``."""
    try:
        import minari
    except ImportError as err:
        raise DatasetError("importing from Minari needs Minari: pip install"
                           " 'abco[minari]'") from err
    path = Path(source)
    try:
        if path.is_dir():
            return minari.MinariDataset(path / "data" if (path / "data").is_dir() else path)
        return minari.load_dataset(str(source), download=download)
    except FileNotFoundError as err:
        raise UnknownDatasetError(f"no Minari dataset {source}: neither a folder nor a dataset"
                                  " in Minari's datasets root ($MINARI_DATASETS_PATH);"
                                  f" {err}") from err
    except _READ_ERRORS as err:
        raise CorruptDatasetError(f"cannot read Minari dataset {source}:"
                                  f" {type(err).__name__}: {err}") from err


class _Source:
    """A Minari dataset as abco reads it: spaces, environment, reference scores."""

    def __init__(self, dataset: Any, name: str, kind: str) -> None:
        self.dataset, self.name, self.kind = dataset, name, kind
        self.env_spec = dataset.env_spec
        if self.env_spec is None:
            raise InvalidParameterError(f"Minari dataset {name} records no environment;"
                                        " abco needs one to evaluate a policy in")
        self.env_id = self.env_spec.id
        if abco_envs.is_maze(self.env_id):
            raise InvalidParameterError(f"Minari dataset {name} is of an abco maze, whose"
                                        " datasets are built in (abco data list)")
        self.no_actions = isinstance(dataset.action_space, spaces.Box) \
            and dataset.action_space.shape == (0,)  # abco's export of expert data
        self._env: Any = None
        obs_space = dataset.observation_space
        act_space = self.env().action_space if self.no_actions else dataset.action_space
        check_spaces(obs_space, act_space, f"Minari dataset {name}")
        assert isinstance(obs_space, spaces.Box) and isinstance(act_space, spaces.Discrete)
        self.observation_space: spaces.Box = obs_space
        self.action_space: spaces.Discrete = act_space
        self.metadata = dataset.storage.metadata

    def env(self) -> Any:
        """The dataset's environment (made once, on first use)."""
        if self._env is None:
            try:
                self._env = self.dataset.recover_environment()
            except Exception as exc:  # gym.make of a spec from elsewhere: any error
                raise InvalidParameterError(
                    f"cannot make the environment {self.env_id} of Minari dataset"
                    f" {self.name}: {type(exc).__name__}: {exc}") from exc
        return self._env

    def close(self) -> None:
        if self._env is not None:
            self._env.close()

    def score(self, key: str) -> float | None:
        value = self.metadata.get(key)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                or not np.isfinite(value):
            raise CorruptDatasetError(f"Minari dataset {self.name}: {key} is not a finite"
                                      f" number ({value!r})")
        return float(value)

    def actions(self, ep: Any, where: str) -> np.ndarray:
        raw = ep.infos.get(IDM_EVAL_ACTIONS) if self.no_actions else ep.actions
        if raw is None:
            raise CorruptDatasetError(f"{where}: no actions (and no infos['{IDM_EVAL_ACTIONS}'])")
        actions = np.asarray(raw)
        n = int(self.action_space.n)
        if actions.dtype.kind not in "iu" or actions.ndim != 1 or len(actions) != len(ep) \
                or (len(actions) and (actions.min() < 0 or actions.max() >= n)):
            raise CorruptDatasetError(f"{where}: actions are not {len(ep)} integers of"
                                      f" Discrete({n})")
        return actions.astype(np.int64)

    def episodes(self, on_skip: Callable[[int], object]) -> Iterator[EpisodeColumns]:
        """The episodes with a step, checked and bounded (see the module docstring)."""
        row_bytes = int(np.prod(self.observation_space.shape)) \
            * self.observation_space.dtype.itemsize
        steps = rows = 0
        metadata = self.dataset.storage.get_episode_metadata(self.dataset.episode_indices)
        for i, (ep, meta) in enumerate(zip(self.dataset.iterate_episodes(), metadata)):
            where = f"Minari dataset {self.name}, episode {i}"
            n = len(ep)
            if n == 0:
                on_skip(i)
                continue
            steps, rows = steps + n, rows + n + 1
            if steps > MAX_TRANSITIONS or rows * row_bytes > MAX_FRAME_BYTES:
                raise InvalidParameterError(
                    f"Minari dataset {self.name} holds more than abco imports: at most"
                    f" {MAX_TRANSITIONS:,} steps and {MAX_FRAME_BYTES >> 30} GiB of"
                    " observations")
            truncations = np.asarray(ep.truncations, dtype=bool).copy()
            terminations = np.asarray(ep.terminations, dtype=bool)
            if len(truncations) == n and not (terminations[-1] or truncations[-1]):
                truncations[-1] = True  # cut short when collected: a truncation
            seed = meta.get("seed") if isinstance(meta, dict) else None
            yield EpisodeColumns(
                clean_observations(ep.observations, self.observation_space, where),
                self.actions(ep, where), np.asarray(ep.rewards, dtype=np.float64),
                terminations, truncations, int(seed) if isinstance(seed, int) else -1)

    def reference(self, episodes: int) -> Callable[[np.ndarray], ReferenceReturns]:
        """Minari's scores, or measured (see the module docstring), given the returns."""
        random, expert = self.score("ref_min_score"), self.score("ref_max_score")
        if random is None:
            env = self.env()

            def uniform(seed: int) -> Callable[[Any], int]:
                rng = np.random.default_rng(seed)
                return lambda obs: int(rng.integers(env.action_space.n))

            random = mean_return(uniform, env, episodes, REFERENCE_SEED)
        measured = random

        def finish(returns: np.ndarray) -> ReferenceReturns:
            mean = float(returns.mean()) if expert is None else expert
            return ReferenceReturns(expert_mean=mean, random_mean=measured)

        return finish


def _env_kwargs(env_spec: Any) -> dict[str, Any]:
    """The ``gymnasium.make`` keyword arguments the dataset's env spec adds to the registered
    one's (all of its own when its id is not registered here)."""
    import gymnasium as gym

    try:
        registered = gym.spec(env_spec.id)
    except gym.error.Error:
        registered = None
    kwargs = {k: v for k, v in env_spec.kwargs.items()
              if registered is None or registered.kwargs.get(k, object()) != v}
    if registered is not None and env_spec.max_episode_steps != registered.max_episode_steps:
        kwargs["max_episode_steps"] = env_spec.max_episode_steps
    try:
        to_json(kwargs)
    except (TypeError, ValueError):
        logger.warning("the env kwargs of %s are not JSON; the file records none", env_spec.id)
        return {}
    return kwargs


def import_minari(source: str | os.PathLike[str], *, out: str | os.PathLike[str] | None = None,
                  id: str | None = None, kind: str = "expert", download: bool = False,
                  reference_episodes: int = 100, overwrite: bool = False,
                  progress: bool = True, home: str | os.PathLike[str] | None = None) -> Path:
    """Write Minari dataset ``source`` as an abco dataset; return the file.

    Args:
        source: A Minari dataset id (in Minari's datasets root) or the path of a Minari
            dataset's folder (or of its ``data`` folder).
        out: The file to write (see :func:`abco_data.record` for ``out`` and ``id``).
        id: A user dataset id to register the file under (``local/NAME-v0``).
        kind: ``"expert"`` (actions kept as ``idm_eval_actions``) or ``"pre"``.
        download: Let Minari download a dataset it does not hold (``minari.load_dataset``).
        reference_episodes: Episodes of uniform random actions when the dataset has no
            ``ref_min_score``.
        overwrite: Replace a registered user dataset of the same id.
        progress: A progress bar on stderr.
        home: The abco data home (default ``$ABCO_DATA_HOME``).

    Raises:
        DatasetError: Minari is not installed.
        UnknownDatasetError: No such Minari dataset.
        InvalidParameterError: A bad argument or id, spaces abco does not store, no
            environment, more data than abco imports.
        CorruptDatasetError: Data Minari cannot read, or that breaks abco's rules.
        DatasetWriteError: Writing failed; the target was left as it was.

    Example:
        >>> import tempfile, os, abco_data
        >>> from abco_data.interop.minari_export import export_to_minari
        >>> tmp = tempfile.mkdtemp()
        >>> pole = abco_data.generate("abco/cartpole-expert-v0", os.path.join(tmp, "c.hdf5"),
        ...     progress=False, episodes=2, reference_episodes=1, reference_expert_episodes=1)
        >>> folder = export_to_minari(pole, datasets_root=os.path.join(tmp, "minari"))
        >>> path = import_minari(folder, out=os.path.join(tmp, "back.hdf5"), progress=False)
        >>> back = abco_data.check_dataset(path, kind="expert", env_id="CartPole-v1")
        >>> back.id, back.num_transitions == abco_data.open_dataset(pole).num_transitions
        ('local/back-v0', True)
    """
    kind = kind_name(kind)
    path, dataset_id, register = user_target(out, id, overwrite=overwrite, home=home)
    check_target(path)
    check_params(dataset_id, "", "pre_demonstrations", {"reference_episodes": reference_episodes})
    dataset = _open(source, download)
    name = str(getattr(dataset, "id", source))
    src = _Source(dataset, name, kind)
    skipped: list[int] = []
    try:
        attrs = {"dataset_id": dataset_id, "env_id": src.env_id,
                 "env_spec": env_spec_json(src.env_spec),
                 "env_kwargs": to_json(_env_kwargs(src.env_spec)),
                 "generator": GENERATOR, "generator_version": GENERATOR_VERSION, "seed": 0,
                 "creation_params": to_json({
                     "source": str(source), "minari_id": name,
                     "minari_version": str(dataset.minari_version),
                     "reference_episodes": reference_episodes})}
        reference = src.reference(reference_episodes)
        with progress_bar(total=dataset.total_episodes, unit="episodes", desc=dataset_id,
                          disable=not progress, leave=False) as bar:
            write_episodes(path, src.episodes(skipped.append), kind=kind, attrs=attrs,
                           observation_space=src.observation_space,
                           action_space=src.action_space, reference=reference,
                           on_episode=lambda n: bar.update(1))
    except _READ_ERRORS as err:  # HDF5 and Minari reading the episodes (ours are raised)
        if isinstance(err, DatasetError):
            raise
        raise CorruptDatasetError(f"cannot read Minari dataset {name}:"
                                  f" {type(err).__name__}: {err}") from err
    finally:
        src.close()
    if skipped:
        logger.warning("left out %d episode(s) of %s without a step", len(skipped), name)
    if register:
        register_user_dataset(dataset_id, path, env_id=src.env_id, kind=kind, home=home)
    return path

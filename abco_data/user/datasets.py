"""The user manifest: where each of the user's own datasets is, and what its bytes are.

A dataset recorded or imported under an id of the user's own (:mod:`abco_data.user.ids`,
``local/cartpole-mine-v0``) is registered in ``user-datasets.json`` in the abco data home
(``$ABCO_DATA_HOME``, default ``~/.cache/abco/datasets``)::

    {"format": "abco-user-datasets", "version": 1,
     "datasets": {"local/cartpole-mine-v0": {"path": "local/cartpole-mine-v0.hdf5",
                  "size": 123, "sha256": "<64 hex>", "env_id": "CartPole-v1",
                  "kind": "expert"}}}

A path inside the data home is stored relative to it (the home can move), any other one
absolute. Every reader checks a file holding a registered id against its entry, as it checks
a built-in file against the shipped manifest: :func:`load_user_dataset` (what
:func:`abco_data.load` does for a user id), :func:`abco_data.verify` and
:func:`abco_data.check_dataset`. The manifest is rewritten whole (temporary file, then
``os.replace``) under an operating-system lock (``filelock``) on ``user-datasets.json.lock``,
so two processes registering at once both land.

Example:
    >>> import tempfile
    >>> home = tempfile.mkdtemp()
    >>> user_dataset_path("local/cartpole-mine-v0", home).relative_to(home).as_posix()
    'local/cartpole-mine-v0.hdf5'
    >>> read_user_manifest(home)
    {}
"""

from __future__ import annotations

import errno
import json
import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path

from filelock import FileLock, Timeout

from abco_data.dataset import Dataset, open_dataset
from abco_data.errors import (
    ChecksumError,
    DatasetError,
    DatasetFileNotFoundError,
    DatasetWriteError,
    InvalidParameterError,
    UnknownDatasetError,
)
from abco_data.format import KINDS
from abco_data.format.files import atomic_target, file_digest
from abco_data.hub.manifest import data_home
from abco_data.user.ids import check_user_id, split_user_id, user_id_for_file

__all__ = ["USER_MANIFEST_NAME", "LOCK_TIMEOUT", "UserDatasetEntry", "user_manifest_path",
           "user_dataset_path", "read_user_manifest", "user_entry", "register_user_dataset",
           "user_dataset_file", "load_user_dataset", "user_target"]

#: The user manifest's file name in the data home.
USER_MANIFEST_NAME = "user-datasets.json"
#: Seconds to wait for another process's lock on the user manifest.
LOCK_TIMEOUT = 60.0
_FORMAT = "abco-user-datasets"
_HEX64 = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True)
class UserDatasetEntry:
    """One registered user dataset.

    Attributes:
        dataset_id: Its id (``local/cartpole-mine-v0``).
        path: The file (absolute).
        size: Size in bytes.
        sha256: Lower-case hex sha256 of the file's bytes.
        env_id: The Gymnasium id of its environment.
        kind: ``"expert"`` or ``"pre_demonstrations"``.
    """

    dataset_id: str
    path: Path
    size: int
    sha256: str
    env_id: str
    kind: str


def _home(home: str | os.PathLike[str] | None) -> Path:
    return Path(home).expanduser() if home is not None else data_home()


def user_manifest_path(home: str | os.PathLike[str] | None = None) -> Path:
    """The user manifest of data home ``home`` (default :func:`abco_data.data_home`)."""
    return _home(home) / USER_MANIFEST_NAME


def user_dataset_path(dataset_id: str, home: str | os.PathLike[str] | None = None) -> Path:
    """Where a user dataset recorded by id goes: ``<home>/<namespace>/<NAME-vN>.hdf5``
    (built-in files lie in the home itself, so the two never meet).

    Raises:
        InvalidParameterError: Not a user id.
    """
    namespace, name = split_user_id(dataset_id)
    return _home(home) / namespace / f"{name}.hdf5"


def _entry(dataset_id: object, item: object, where: Path) -> UserDatasetEntry:
    """One entry of the manifest ``where``, checked."""
    if not isinstance(dataset_id, str) or not isinstance(item, dict):
        raise DatasetError(f"invalid user dataset manifest {where}: the entry of"
                           f" {dataset_id!r} must be an object")
    path, size, sha256 = item.get("path"), item.get("size"), item.get("sha256")
    env_id, kind = item.get("env_id"), item.get("kind")
    if not (isinstance(path, str) and path and isinstance(size, int)
            and not isinstance(size, bool) and size >= 0 and isinstance(sha256, str)
            and _HEX64.fullmatch(sha256) and isinstance(env_id, str) and kind in KINDS):
        raise DatasetError(f"invalid user dataset manifest {where}: the entry of"
                           f" {dataset_id!r} needs a path, a byte count size, a 64-hex sha256,"
                           " an env_id and a kind")
    return UserDatasetEntry(dataset_id, where.parent / path, size, sha256, env_id, str(kind))


def read_user_manifest(home: str | os.PathLike[str] | None = None
                       ) -> dict[str, UserDatasetEntry]:  # fmt: skip
    """Every registered user dataset, by id (none when there is no user manifest).

    Raises:
        DatasetError: The manifest cannot be read or is not one (the message names it).
    """
    where = user_manifest_path(home)
    try:
        raw = json.loads(where.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as err:
        raise DatasetError(f"cannot read the user dataset manifest {where}: {err}") from err
    if not isinstance(raw, dict) or raw.get("format") != _FORMAT \
            or not isinstance(raw.get("datasets"), dict):
        raise DatasetError(f"invalid user dataset manifest {where}: expected an object with"
                           f" format {_FORMAT!r} and a 'datasets' object")
    return {k: _entry(k, v, where) for k, v in raw["datasets"].items()}


def user_entry(dataset_id: str, home: str | os.PathLike[str] | None = None
               ) -> UserDatasetEntry | None:  # fmt: skip
    """The registered entry of ``dataset_id``, or None."""
    return read_user_manifest(home).get(dataset_id)


def _stored_path(path: Path, home: Path) -> str:
    path = Path(os.path.abspath(path))
    try:
        return path.relative_to(Path(os.path.abspath(home))).as_posix()
    except ValueError:
        return str(path)


def register_user_dataset(dataset_id: str, path: str | os.PathLike[str], *, env_id: str,
                          kind: str, home: str | os.PathLike[str] | None = None
                          ) -> UserDatasetEntry:  # fmt: skip
    """Record ``path``'s size and sha256 as those of user dataset ``dataset_id``.

    The file's digest is taken under the manifest's lock, so the entry is that of the file
    on disk when the manifest is written, even if another process wrote the file meanwhile.

    Raises:
        InvalidParameterError: Not a user id.
        DatasetWriteError: The manifest cannot be written, or another process held its lock
            for more than :data:`LOCK_TIMEOUT` seconds.
    """
    check_user_id(dataset_id)
    where = user_manifest_path(home)
    try:
        where.parent.mkdir(parents=True, exist_ok=True)
        with FileLock(f"{where}.lock", timeout=LOCK_TIMEOUT):
            entries = read_user_manifest(home)
            size, sha256 = file_digest(path)
            entry = UserDatasetEntry(dataset_id, Path(os.path.abspath(path)), size, sha256,
                                     env_id, kind)
            entries[dataset_id] = entry
            datasets = {k: {**asdict(e), "path": _stored_path(e.path, where.parent)}
                        for k, e in sorted(entries.items())}
            for item in datasets.values():
                del item["dataset_id"]
            text = json.dumps({"format": _FORMAT, "version": 1, "datasets": datasets},
                              indent=1, sort_keys=True)
            with atomic_target(where, "writing") as tmp:
                tmp.write_text(text + "\n", encoding="utf-8")
    except Timeout as err:
        raise DatasetWriteError(errno.EBUSY, f"another process has held the lock on {where}"
                                f" for more than {LOCK_TIMEOUT:g} s", str(where)) from err
    except DatasetError:
        raise
    except OSError as err:
        raise DatasetWriteError(err.errno or errno.EIO, f"cannot write the user dataset"
                                f" manifest {where}: {err}", str(where)) from err
    return entry


def user_dataset_file(dataset_id: str, home: str | os.PathLike[str] | None = None) -> Path:
    """The registered file of ``dataset_id``, once its size and sha256 match its entry.

    Raises:
        InvalidParameterError: Not a user id.
        UnknownDatasetError: No user dataset of that id is registered.
        DatasetFileNotFoundError: The registered file is gone.
        ChecksumError: Its bytes differ from the entry (the message names the file).
    """
    check_user_id(dataset_id)
    entry = user_entry(dataset_id, home)
    if entry is None:
        raise UnknownDatasetError(
            f"unknown dataset id {dataset_id!r}: no user dataset of that id is registered in"
            f" {user_manifest_path(home)} (record one with abco data record --id"
            f" {dataset_id}, or import one with abco data import-minari --id {dataset_id})")
    try:
        size, sha256 = file_digest(entry.path)
    except FileNotFoundError:
        raise DatasetFileNotFoundError(
            errno.ENOENT, f"{entry.path}: the file of user dataset {dataset_id} is gone"
            f" (registered in {user_manifest_path(home)})", str(entry.path)) from None
    if (size, sha256) != (entry.size, entry.sha256):
        raise ChecksumError(
            f"{entry.path}: {size} bytes with sha256 {sha256} do not match the user manifest"
            f" entry of {dataset_id}: {entry.size} bytes with sha256 {entry.sha256} (the file"
            " changed since it was recorded)")
    return entry.path


def load_user_dataset(dataset_id: str, home: str | os.PathLike[str] | None = None, *,
                      layouts: int | None = None) -> Dataset:
    """Open registered user dataset ``dataset_id`` once its bytes match its entry (what
    :func:`abco_data.load` does for a user id).

    Raises:
        UnknownDatasetError, DatasetFileNotFoundError, ChecksumError: See
            :func:`user_dataset_file`.
        CorruptDatasetError: The file holds another id, or is not a readable dataset.
        WrongKindError: ``layouts`` given: user datasets have no maze layouts.
    """
    ds = open_dataset(user_dataset_file(dataset_id, home), dataset_id=dataset_id)
    return ds if layouts is None else ds.first_layouts(layouts)


def user_target(out: str | os.PathLike[str] | None, dataset_id: str | None, *,
                overwrite: bool, home: str | os.PathLike[str] | None = None
                ) -> tuple[Path, str, bool]:  # fmt: skip
    """``(file, id, register)`` of a new user dataset written to ``out`` and/or as
    ``dataset_id`` (see :func:`abco_data.record`).

    Raises:
        InvalidParameterError: Neither given, a bad id, an id already registered (without
            ``overwrite``), or a file name whose derived id is a registered one.
    """
    if out is None and dataset_id is None:
        raise InvalidParameterError("say where the dataset goes: a file (out, --out FILE)"
                                    " and/or a user dataset id (id, --id ID)")
    if dataset_id is None:
        derived = user_id_for_file(out or "")
        taken = user_entry(derived, home)
        if taken is not None:
            raise InvalidParameterError(
                f"the id {derived} that {out} would hold is a registered user dataset"
                f" ({taken.path}); name this one with an id of its own (--id ID)")
        return Path(out or ""), derived, False
    check_user_id(dataset_id)
    taken = user_entry(dataset_id, home)
    if taken is not None and not overwrite:
        raise InvalidParameterError(f"user dataset {dataset_id} is already registered"
                                    f" ({taken.path}); replace it with overwrite=True"
                                    " (--overwrite) or choose another id or version")
    path = Path(out) if out is not None else user_dataset_path(dataset_id, home)
    return path, dataset_id, True

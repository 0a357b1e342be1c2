"""The abco cache and the manifest shipped in the package: where files go, what their bytes are.

The manifest (``abco_data/manifest.json``, or the file named by ``$ABCO_DATA_MANIFEST`` or by a
``manifest`` argument) pins the published files: the dataset repo, its revision, and the size
and sha256 of every dataset file::

    {"revision": "<40-hex commit of the dataset repo>",
     "repo_id": "abco-datasets/abco",
     "files": {"abco/maze5x5-expert-v0": {"filename": "maze5x5-expert-v0.hdf5",
                                          "size": 123, "sha256": "<64 hex>"}}}

A downloaded file and a locally generated one are checked against the same entry, since
generation is deterministic.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from huggingface_hub.utils import HFValidationError, validate_repo_id

from abco_data.errors import (
    ChecksumError,
    DatasetError,
    InvalidParameterError,
    UnknownDatasetError,
)
from abco_data.format.files import atomic_target, file_digest
from abco_data.registry import DATASET_IDS, spec

__all__ = [
    "CACHE_ENV",
    "DEFAULT_REPO_ID",
    "MANIFEST_ENV",
    "Manifest",
    "ManifestEntry",
    "as_manifest",
    "cache_filename",
    "cached_path",
    "check_known_id",
    "check_repo_id",
    "data_home",
    "default_cache_dir",
    "default_manifest_path",
    "file_digest",
    "install_verified",
    "known_ids",
    "read_manifest",
    "verify_file",
]

logger = logging.getLogger(__name__)

#: The dataset repo on the Hub that holds the published files.
DEFAULT_REPO_ID = "abco-datasets/abco"
#: Environment variable naming another manifest file (tests, mirrors).
MANIFEST_ENV = "ABCO_DATA_MANIFEST"
#: Environment variable naming the abco dataset cache folder.
CACHE_ENV = "ABCO_DATA_HOME"
_HEX64 = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True)
class ManifestEntry:
    """The published file of one dataset.

    Attributes:
        filename: File name in the dataset repo and in the abco cache.
        size: Size in bytes.
        sha256: Lower-case hex sha256 of the file's bytes.
    """

    filename: str
    size: int
    sha256: str


@dataclass(frozen=True)
class Manifest:
    """The manifest shipped in the package: where the datasets are and what their bytes are.

    Attributes:
        revision: Commit of the dataset repo the files are pinned to (None: nothing published).
        repo_id: Dataset repo on the Hub.
        files: Dataset id -> :class:`ManifestEntry`.
        path: The file this manifest was read from, if any.
    """

    revision: str | None
    repo_id: str = DEFAULT_REPO_ID
    files: Mapping[str, ManifestEntry] = field(default_factory=dict)
    path: Path | None = None

    def entry(self, dataset_id: str) -> ManifestEntry | None:
        """The entry of ``dataset_id``, or None when the manifest does not list it."""
        return self.files.get(dataset_id)


def check_repo_id(repo_id: object, what: str = "Hub repo id") -> str:
    """``repo_id`` if it is a valid ``owner/name`` Hub repo id (huggingface_hub's own rules).

    Raises:
        InvalidParameterError: Anything else (``../../x``, ``a/b/c``, ``name`` alone...).

    Example:
        >>> check_repo_id("abco-datasets/abco")
        'abco-datasets/abco'
    """
    try:
        if not isinstance(repo_id, str) or repo_id.count("/") != 1:
            raise HFValidationError("it must read 'owner/name'")
        validate_repo_id(repo_id)
    except HFValidationError as err:
        reason = str(err).strip().splitlines()[0] if str(err).strip() else "not valid"
        raise InvalidParameterError(f"invalid {what} {repo_id!r}: {reason}") from None
    return repo_id


def default_manifest_path() -> Path:
    """``$ABCO_DATA_MANIFEST`` if set, else the ``manifest.json`` shipped at the top of the
    package (``abco_data/manifest.json``)."""
    override = os.environ.get(MANIFEST_ENV)
    if override:
        return Path(override).expanduser()
    return Path(__file__).parents[1] / "manifest.json"


def read_manifest(path: str | os.PathLike[str] | None = None) -> Manifest:
    """Read and check a manifest file.

    Args:
        path: The manifest to read; default :func:`default_manifest_path`.

    Returns:
        The manifest. A missing default manifest reads as an empty one (nothing published).

    Raises:
        DatasetError: The file cannot be read or is not a valid manifest (the message names it).
    """
    explicit = path is not None or bool(os.environ.get(MANIFEST_ENV))
    manifest_path = Path(path).expanduser() if path is not None else default_manifest_path()
    if not manifest_path.exists() and not explicit:
        logger.debug("no manifest at %s: nothing is published", manifest_path)
        return Manifest(revision=None, path=manifest_path)
    try:
        raw = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DatasetError(f"cannot read the dataset manifest {manifest_path}: {err}") from err

    def bad(problem: str) -> DatasetError:
        return DatasetError(f"invalid dataset manifest {manifest_path}: {problem}")

    if not isinstance(raw, dict):
        raise bad("the top level must be a JSON object")
    revision = raw.get("revision")
    if revision is not None and not isinstance(revision, str):
        raise bad(f"'revision' must be a string, got {revision!r}")
    repo_id = raw.get("repo_id", DEFAULT_REPO_ID)
    try:
        check_repo_id(repo_id, "'repo_id'")
    except InvalidParameterError as err:
        raise bad(str(err)) from None
    files_raw = raw.get("files", {})
    if not isinstance(files_raw, dict):
        raise bad("'files' must be an object mapping dataset ids to entries")
    files: dict[str, ManifestEntry] = {}
    for dataset_id, item in files_raw.items():
        if not isinstance(item, dict):
            raise bad(f"the entry of {dataset_id!r} must be an object")
        filename, size, sha256 = item.get("filename"), item.get("size"), item.get("sha256")
        if not isinstance(filename, str) or not filename or "/" in filename or "\\" in filename:
            raise bad(f"the entry of {dataset_id!r} needs a plain 'filename', got {filename!r}")
        if not isinstance(size, int) or isinstance(size, bool) or size < 0:
            raise bad(f"the entry of {dataset_id!r} needs a byte count 'size', got {size!r}")
        if not isinstance(sha256, str) or not _HEX64.fullmatch(sha256.lower()):
            raise bad(f"the entry of {dataset_id!r} needs a 64-hex 'sha256', got {sha256!r}")
        files[dataset_id] = ManifestEntry(filename=filename, size=size, sha256=sha256.lower())
    return Manifest(revision=revision or None, repo_id=repo_id, files=files, path=manifest_path)


def as_manifest(manifest: Manifest | str | os.PathLike[str] | None) -> Manifest:
    """``manifest`` itself, or the manifest read from that path (None: the default one)."""
    return manifest if isinstance(manifest, Manifest) else read_manifest(manifest)


# --------------------------------------------------------------------------- ids and paths


def known_ids(manifest: Manifest | None = None) -> tuple[str, ...]:
    """The dataset ids abco knows: ``abco_data.DATASET_IDS`` plus any listed in the manifest."""
    ids = list(DATASET_IDS)
    if manifest is not None:
        ids += [dataset_id for dataset_id in manifest.files if dataset_id not in ids]
    return tuple(ids)


def check_known_id(dataset_id: str, manifest: Manifest) -> None:
    """Raise :class:`UnknownDatasetError` (listing the known ids) for an unknown id."""
    ids = known_ids(manifest)
    if dataset_id not in ids:
        raise UnknownDatasetError(
            f"unknown dataset id {dataset_id!r}; known ids: {', '.join(ids)}"
        )


def cache_filename(dataset_id: str, manifest: Manifest) -> str:
    """The file name of ``dataset_id`` in the cache and in the dataset repo."""
    entry = manifest.entry(dataset_id)
    if entry is not None:
        return entry.filename
    if dataset_id in DATASET_IDS:
        return str(spec(dataset_id).filename)
    return dataset_id.rsplit("/", 1)[-1] + ".hdf5"


def default_cache_dir() -> Path:
    """``$ABCO_DATA_HOME`` if set, else ``~/.cache/abco/datasets``."""
    override = os.environ.get(CACHE_ENV)
    return Path(override).expanduser() if override else Path.home() / ".cache/abco/datasets"


#: The name ``abco_data`` has always exported for :func:`default_cache_dir`.
data_home = default_cache_dir


def cached_path(
    dataset_id: str,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    manifest: Manifest | str | os.PathLike[str] | None = None,
) -> Path:
    """Where the abco cache keeps ``dataset_id`` (the file may not exist yet).

    Args:
        dataset_id: A dataset id such as ``"abco/maze5x5-expert-v0"``.
        cache_dir: The cache folder; default :func:`default_cache_dir`.
        manifest: A manifest or the path of one; default the shipped manifest.

    Raises:
        UnknownDatasetError: ``dataset_id`` is not a known id (the message lists them).
    """
    man = as_manifest(manifest)
    check_known_id(dataset_id, man)
    folder = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    return folder / cache_filename(dataset_id, man)


# --------------------------------------------------------------------------- verification


def verify_file(
    path: str | os.PathLike[str],
    entry: ManifestEntry,
    *,
    dataset_id: str,
    what: str = "file",
    shown_as: str | os.PathLike[str] | None = None,
) -> None:
    """Check a file's size and sha256 against its manifest entry.

    Args:
        path: The file to check.
        entry: Its manifest entry.
        dataset_id: The dataset id, for the message.
        what: What the file is ("cached file", "downloaded file", ...), for the message.
        shown_as: The name to give the file in the message; default ``path``.

    Raises:
        ChecksumError: The size or the sha256 differs; the message names the file and gives the
            expected and the actual size and digest.
    """
    size, sha256 = file_digest(path)
    if size != entry.size or sha256 != entry.sha256:
        raise ChecksumError(
            f"{what} {shown_as or path} does not match the manifest entry of {dataset_id}: "
            f"expected {entry.size} bytes with sha256 {entry.sha256}, "
            f"got {size} bytes with sha256 {sha256}"
        )


def install_verified(source: Path, target: Path, entry: ManifestEntry, dataset_id: str,
                     what: str) -> Path:
    """Put a copy of ``source`` at ``target`` once it matches ``entry`` (atomically).

    The copy is a hard link when ``source`` is on the same file system, else a byte copy.

    Raises:
        ChecksumError: The copy differs from ``entry``; ``target`` was left as it was.
    """
    with atomic_target(target, "incoming") as tmp:
        try:
            os.link(os.path.realpath(source), tmp)
        except OSError:
            shutil.copyfile(source, tmp)
        verify_file(tmp, entry, dataset_id=dataset_id, what=what, shown_as=source)
    return target

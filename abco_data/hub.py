"""Getting a dataset: the local cache, then the Hugging Face Hub, then local generation.

:func:`load` looks for a dataset in three places, in order:

1. the abco cache (``$ABCO_DATA_HOME`` or ``~/.cache/abco/datasets``): a file found there is
   checked (size and sha256) against the manifest shipped in the package; one that fails is
   reported in a log warning naming the file and both digests, and replaced, never used;
2. the Hugging Face Hub: the file is fetched with :func:`huggingface_hub.hf_hub_download` from the
   dataset repo at the revision the manifest pins (through the huggingface_hub cache, so an
   interrupted download resumes), checked against the manifest, and moved into the abco cache
   atomically;
3. local generation with :func:`abco_data.generate`, whose bytes equal the published ones, so the
   same manifest entry checks them.

Offline (``offline=True`` or ``HF_HUB_OFFLINE=1``) no request is sent: a copy already in the
huggingface_hub cache is still used, and otherwise the dataset is generated. The Hub endpoint and
the huggingface_hub cache follow ``HF_ENDPOINT``, ``HF_HOME`` and ``HF_HUB_CACHE`` as they are
when a function is called. Nothing half-written ever has a cache file's name: every file is
written under a hidden temporary name in the cache folder and renamed with :func:`os.replace`
once verified.

The manifest (``abco_data/manifest.json``, or the file named by ``$ABCO_DATA_MANIFEST`` or by the
``manifest`` argument) reads::

    {"revision": "<40-hex commit of the dataset repo>",
     "repo_id": "abco-datasets/abco",
     "files": {"abco/maze5x5-expert-v0": {"filename": "maze5x5-expert-v0.hdf5",
                                          "size": 123, "sha256": "<64 hex>"}}}

Example:
    >>> from abco_data.hub import cached_path
    >>> cached_path("abco/maze5x5-expert-v0", cache_dir="/data/abco").parent.as_posix()
    '/data/abco'
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import shutil
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from abco_data.errors import (
    ChecksumError,
    DatasetError,
    DatasetNotAvailableError,
    UnknownDatasetError,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from abco_data import Dataset

__all__ = [
    "DEFAULT_REPO_ID",
    "Manifest",
    "ManifestEntry",
    "cached_path",
    "dataset_card",
    "default_cache_dir",
    "download",
    "fetch",
    "file_digest",
    "known_ids",
    "load",
    "push",
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
#: License written into the dataset card.
CARD_LICENSE = "mit"

# The naming rule of the contract, used only while abco_data.DATASET_IDS does not exist.
_NAMES = ("maze3x3", "maze5x5", "maze10x10", "cartpole", "acrobot", "mountaincar")
_KINDS = ("expert", "pre")
_FALLBACK_IDS = tuple(f"abco/{name}-{kind}-v0" for name in _NAMES for kind in _KINDS)
_HEX40 = re.compile(r"[0-9a-f]{40}")
_HEX64 = re.compile(r"[0-9a-f]{64}")
_READ_CHUNK = 1 << 20


# --------------------------------------------------------------------------- manifest


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


def default_manifest_path() -> Path:
    """``$ABCO_DATA_MANIFEST`` if set, else the ``manifest.json`` shipped next to this module."""
    override = os.environ.get(MANIFEST_ENV)
    if override:
        return Path(override).expanduser()
    return Path(__file__).with_name("manifest.json")


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
    if not isinstance(repo_id, str) or repo_id.count("/") != 1:
        raise bad(f"'repo_id' must read 'owner/name', got {repo_id!r}")
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


def _as_manifest(manifest: Manifest | str | os.PathLike[str] | None) -> Manifest:
    return manifest if isinstance(manifest, Manifest) else read_manifest(manifest)


# --------------------------------------------------------------------------- ids and paths


def known_ids(manifest: Manifest | None = None) -> tuple[str, ...]:
    """The dataset ids abco knows: ``abco_data.DATASET_IDS`` plus any listed in the manifest."""
    import abco_data

    registry = getattr(abco_data, "DATASET_IDS", None)
    ids = list(registry) if registry else list(_FALLBACK_IDS)
    if manifest is not None:
        ids += [dataset_id for dataset_id in manifest.files if dataset_id not in ids]
    return tuple(ids)


def _check_id(dataset_id: str, manifest: Manifest) -> None:
    ids = known_ids(manifest)
    if dataset_id not in ids:
        raise UnknownDatasetError(
            f"unknown dataset id {dataset_id!r}; known ids: {', '.join(ids)}"
        )


def _filename(dataset_id: str, manifest: Manifest) -> str:
    entry = manifest.entry(dataset_id)
    if entry is not None:
        return entry.filename
    import abco_data

    spec = getattr(abco_data, "spec", None)
    if spec is not None and dataset_id in getattr(abco_data, "DATASET_IDS", ()):
        return str(spec(dataset_id).filename)
    return dataset_id.rsplit("/", 1)[-1] + ".hdf5"


def default_cache_dir() -> Path:
    """``$ABCO_DATA_HOME`` if set, else ``~/.cache/abco/datasets``."""
    override = os.environ.get(CACHE_ENV)
    return Path(override).expanduser() if override else Path.home() / ".cache/abco/datasets"


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
    man = _as_manifest(manifest)
    _check_id(dataset_id, man)
    folder = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    return folder / _filename(dataset_id, man)


# --------------------------------------------------------------------------- verification


def file_digest(path: str | os.PathLike[str]) -> tuple[int, str]:
    """Return ``(size in bytes, hex sha256)`` of a file, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as handle:
        while chunk := handle.read(_READ_CHUNK):
            digest.update(chunk)
            size += len(chunk)
    return size, digest.hexdigest()


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


@contextmanager
def _temporary_name(target: Path, tag: str) -> Iterator[Path]:
    """A hidden, unique name next to ``target``, removed on exit unless it was renamed."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.stem}.{uuid.uuid4().hex[:12]}.{tag}{target.suffix}")
    try:
        yield tmp
    finally:
        tmp.unlink(missing_ok=True)


def _install(source: Path, target: Path, entry: ManifestEntry, dataset_id: str, what: str) -> Path:
    """Put a verified copy of ``source`` at ``target`` (hard link if possible, else a copy)."""
    with _temporary_name(target, "incoming") as tmp:
        try:
            os.link(os.path.realpath(source), tmp)
        except OSError:
            shutil.copyfile(source, tmp)
        verify_file(tmp, entry, dataset_id=dataset_id, what=what, shown_as=source)
        os.replace(tmp, target)
    return target


# --------------------------------------------------------------------------- huggingface_hub glue


def _env_flag(name: str) -> bool | None:
    value = os.environ.get(name)
    if value is None or value == "":
        return None
    return value.strip().upper() in {"1", "ON", "YES", "TRUE"}


def _is_offline(offline: bool | None) -> bool:
    """``offline`` if given, else ``HF_HUB_OFFLINE`` as set now, else huggingface_hub's flag."""
    if offline is not None:
        return bool(offline)
    for name in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE"):
        flag = _env_flag(name)
        if flag is not None:
            return flag
    from huggingface_hub import constants

    return bool(constants.HF_HUB_OFFLINE)


def _hf_endpoint() -> str | None:
    """``HF_ENDPOINT`` as set now (None: huggingface_hub's own default)."""
    value = os.environ.get("HF_ENDPOINT")
    return value.rstrip("/") if value else None


def _hf_cache_dir() -> str | None:
    """The huggingface_hub cache as the environment sets it now (None: its own default)."""
    for name in ("HF_HUB_CACHE", "HUGGINGFACE_HUB_CACHE"):
        if os.environ.get(name):
            return os.path.expanduser(os.path.expandvars(os.environ[name]))
    if os.environ.get("HF_HOME"):
        return os.path.join(os.path.expanduser(os.path.expandvars(os.environ["HF_HOME"])), "hub")
    return None


class _SilentBar:
    """A do-nothing progress bar for ``hf_hub_download(tqdm_class=...)`` when progress=False."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.n = 0

    def __enter__(self) -> _SilentBar:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def update(self, n: float | None = 1) -> None:
        """Ignore progress."""

    def close(self) -> None:
        """Nothing to close."""


def _transfer_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean "the Hub could not give us the file" (not programming errors)."""
    from huggingface_hub.errors import EntryNotFoundError

    errors: list[type[BaseException]] = [OSError, EntryNotFoundError]
    for module_name in ("httpx2", "httpx", "requests"):
        try:
            module = __import__(module_name)
        except ImportError:
            continue
        base = getattr(module, "HTTPError", None) or getattr(module, "RequestException", None)
        if isinstance(base, type) and issubclass(base, BaseException):
            errors.append(base)
    return tuple(errors)


def _hub_location(manifest: Manifest, revision: str | None) -> str:
    endpoint = _hf_endpoint()
    if endpoint is None:
        from huggingface_hub import constants

        endpoint = constants.ENDPOINT
    return f"{endpoint}/datasets/{manifest.repo_id}@{revision}"


def _hub_file(
    dataset_id: str,
    entry: ManifestEntry,
    manifest: Manifest,
    *,
    revision: str | None,
    progress: bool,
    local_files_only: bool,
    force_download: bool = False,
) -> Path:
    """Path of the file in the huggingface_hub cache, downloading it if needed (not verified)."""
    from huggingface_hub import hf_hub_download

    rev = revision or manifest.revision
    if not rev:
        raise DatasetNotAvailableError(
            f"{dataset_id} is not published: the manifest {manifest.path} pins no Hub revision"
        )
    where = _hub_location(manifest, rev)
    try:
        local = hf_hub_download(
            repo_id=manifest.repo_id,
            filename=entry.filename,
            repo_type="dataset",
            revision=rev,
            cache_dir=_hf_cache_dir(),
            endpoint=_hf_endpoint(),
            local_files_only=local_files_only,
            force_download=force_download,
            tqdm_class=None if progress else _SilentBar,  # type: ignore[arg-type]
        )
    except _transfer_errors() as err:
        if local_files_only:
            reason = "offline and not in the huggingface_hub cache"
        else:
            reason = f"{type(err).__name__}: {str(err).strip().splitlines()[0] if str(err) else ''}"
        raise DatasetNotAvailableError(
            f"could not get {entry.filename} ({dataset_id}) from the Hub at {where}: {reason}"
        ) from err
    return Path(local)


def _evict_hub_copy(path: Path) -> None:
    """Remove a bad file from the huggingface_hub cache (its snapshot link and its blob)."""
    blob = Path(os.path.realpath(path))
    for item in {path, blob}:
        try:
            item.unlink(missing_ok=True)
        except OSError as err:  # pragma: no cover - read-only caches
            logger.warning("could not remove %s from the huggingface_hub cache: %s", item, err)


def _in_hub_cache(entry: ManifestEntry, manifest: Manifest, rev: str) -> bool:
    """Whether the huggingface_hub cache already holds the file at ``rev``."""
    from huggingface_hub import try_to_load_from_cache

    found = try_to_load_from_cache(
        repo_id=manifest.repo_id,
        filename=entry.filename,
        cache_dir=_hf_cache_dir(),
        revision=rev,
        repo_type="dataset",
    )
    return isinstance(found, str)


def _download_into(
    dataset_id: str,
    entry: ManifestEntry,
    manifest: Manifest,
    target: Path,
    *,
    revision: str | None,
    progress: bool,
    offline: bool,
) -> Path:
    """Hub (or huggingface_hub cache) -> verified -> ``target``, atomically."""
    rev = revision or manifest.revision
    had_copy = bool(rev) and _in_hub_cache(entry, manifest, rev or "")
    hub_path = _hub_file(
        dataset_id, entry, manifest, revision=revision, progress=progress, local_files_only=offline
    )
    try:
        return _install(hub_path, target, entry, dataset_id, "downloaded file")
    except ChecksumError as err:
        logger.warning("%s; removing it from the huggingface_hub cache", err)
        _evict_hub_copy(hub_path)
        if offline or not had_copy:
            raise
    # The bad copy was an old one from the huggingface_hub cache: fetch it again, once.
    hub_path = _hub_file(
        dataset_id,
        entry,
        manifest,
        revision=revision,
        progress=progress,
        local_files_only=False,
        force_download=True,
    )
    try:
        return _install(hub_path, target, entry, dataset_id, "downloaded file")
    except ChecksumError:
        _evict_hub_copy(hub_path)
        raise


def _generate_into(
    dataset_id: str, entry: ManifestEntry | None, target: Path, *, progress: bool
) -> Path:
    """Generate ``dataset_id`` locally, verify it, and move it to ``target``."""
    import abco_data

    generate = getattr(abco_data, "generate", None)
    if generate is None:
        raise DatasetNotAvailableError(
            f"cannot generate {dataset_id} locally: abco_data.generate is not available"
        )
    with _temporary_name(target, "generating") as tmp:
        written = Path(generate(dataset_id, tmp, progress=progress) or tmp)
        try:
            if entry is None:
                size, sha256 = file_digest(written)
                logger.warning(
                    "the manifest has no entry for %s: accepting the locally generated file "
                    "unverified (%d bytes, sha256 %s)",
                    dataset_id,
                    size,
                    sha256,
                )
            else:
                verify_file(
                    written,
                    entry,
                    dataset_id=dataset_id,
                    what="locally generated file",
                    shown_as=target,
                )
            os.replace(written, target)
        finally:
            if written != tmp:
                written.unlink(missing_ok=True)
    logger.info("generated %s into %s", dataset_id, target)
    return target


# --------------------------------------------------------------------------- public API


def fetch(
    dataset_id: str,
    *,
    cache_dir: str | os.PathLike[str] | None = None,
    revision: str | None = None,
    offline: bool | None = None,
    progress: bool = True,
    manifest: Manifest | str | os.PathLike[str] | None = None,
) -> Path:
    """Make sure the abco cache holds a verified copy of ``dataset_id`` and return its path.

    Same arguments and order of sources as :func:`load`, which opens the returned file.

    Raises:
        UnknownDatasetError: Unknown id.
        ChecksumError: The locally generated file differs from the manifest entry.
        DatasetNotAvailableError: No source could provide the dataset.
    """
    man = _as_manifest(manifest)
    target = cached_path(dataset_id, cache_dir, manifest=man)
    entry = man.entry(dataset_id)

    if target.exists():
        if entry is None:
            logger.info("using %s (no manifest entry for %s to check it)", target, dataset_id)
            return target
        try:
            verify_file(target, entry, dataset_id=dataset_id, what="cached file")
            return target
        except ChecksumError as err:
            logger.warning("%s; it will be replaced", err)

    offline_now = _is_offline(offline)
    if entry is not None:
        try:
            return _download_into(
                dataset_id,
                entry,
                man,
                target,
                revision=revision,
                progress=progress,
                offline=offline_now,
            )
        except (DatasetNotAvailableError, ChecksumError) as err:
            logger.warning("%s; generating %s locally instead", err, dataset_id)
    elif not offline_now:
        logger.info("%s is not in the manifest, so not on the Hub: generating it", dataset_id)
    return _generate_into(dataset_id, entry, target, progress=progress)


def load(
    dataset_id: str,
    *,
    cache_dir: str | os.PathLike[str] | None = None,
    revision: str | None = None,
    offline: bool | None = None,
    progress: bool = True,
    manifest: Manifest | str | os.PathLike[str] | None = None,
) -> Dataset:
    """Return a dataset from the cache, else the Hub, else local generation.

    Args:
        dataset_id: A dataset id such as ``"abco/maze5x5-expert-v0"``.
        cache_dir: The abco cache folder; default ``$ABCO_DATA_HOME`` or
            ``~/.cache/abco/datasets``.
        revision: Hub revision to download from; default the manifest's pinned commit. The
            bytes are checked against the manifest whatever the revision.
        offline: Never touch the network; default ``HF_HUB_OFFLINE``.
        progress: Show download and generation progress bars.
        manifest: A manifest or the path of one; default ``$ABCO_DATA_MANIFEST`` or the shipped
            ``abco_data/manifest.json``.

    Returns:
        The opened dataset (:func:`abco_data.open_dataset` of the cached file).

    Raises:
        UnknownDatasetError: Unknown id (the message lists the known ones).
        ChecksumError: The locally generated file differs from the manifest entry.
        DatasetNotAvailableError: No source could provide the dataset.
    """
    import abco_data

    path = fetch(
        dataset_id,
        cache_dir=cache_dir,
        revision=revision,
        offline=offline,
        progress=progress,
        manifest=manifest,
    )
    return abco_data.open_dataset(path)


def download(
    dataset_id: str,
    *,
    cache_dir: str | os.PathLike[str] | None = None,
    revision: str | None = None,
    progress: bool = True,
    manifest: Manifest | str | os.PathLike[str] | None = None,
) -> Path:
    """Download ``dataset_id`` from the Hub (never generate), verify it and cache it.

    A copy already in the huggingface_hub cache for the pinned revision is used without a
    request. With ``HF_HUB_OFFLINE=1`` only that copy can be used.

    Args:
        dataset_id: A dataset id.
        cache_dir: The abco cache folder (see :func:`load`).
        revision: Hub revision; default the manifest's pinned commit.
        progress: Show the download progress bar.
        manifest: A manifest or the path of one (see :func:`load`).

    Returns:
        The path of the verified file in the abco cache.

    Raises:
        UnknownDatasetError: Unknown id.
        DatasetNotAvailableError: The manifest lists no published file for the id, or the Hub
            cannot be reached or has no copy.
        ChecksumError: The Hub's file differs from the manifest entry (it is not cached).
    """
    man = _as_manifest(manifest)
    target = cached_path(dataset_id, cache_dir, manifest=man)
    entry = man.entry(dataset_id)
    if entry is None:
        raise DatasetNotAvailableError(
            f"{dataset_id} has no published file: the manifest {man.path} has no entry for it "
            "(generate it locally with abco_data.generate or abco_data.load)"
        )
    return _download_into(
        dataset_id,
        entry,
        man,
        target,
        revision=revision,
        progress=progress,
        offline=_is_offline(None),
    )


# --------------------------------------------------------------------------- push and card


def _root_attributes(path: Path) -> dict[str, Any]:
    import h5py
    import numpy as np

    def plain(value: Any) -> Any:
        if isinstance(value, bytes):
            return value.decode("utf-8", "replace")
        if isinstance(value, np.ndarray):
            return [plain(v) for v in value.tolist()]
        if isinstance(value, np.generic):
            return value.item()
        return value

    with h5py.File(path, "r") as handle:
        return {key: plain(handle.attrs[key]) for key in sorted(handle.attrs)}


def _card_value(value: Any, limit: int = 160) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    text = text.replace("|", "\\|").replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _card_section(dataset_id: str, filename: str, size: int, sha256: str, attrs: dict) -> str:
    lines = [
        f"<!-- abco:{dataset_id} -->",
        f"## `{dataset_id}`",
        "",
        f"File `{filename}`: {size} bytes, sha256 `{sha256}`.",
        "",
        f"- kind: {attrs.get('kind', 'unknown')}",
        f"- environment: {attrs.get('env_id', 'unknown')}",
        f"- format: {attrs.get('format', 'unknown')} version {attrs.get('format_version', '?')}",
        "",
        "| root attribute | value |",
        "| --- | --- |",
    ]
    lines += [f"| `{key}` | {_card_value(value)} |" for key, value in attrs.items()]
    lines += [
        "",
        "```python",
        "import abco_data",
        f'dataset = abco_data.load("{dataset_id}")',
        "```",
        f"<!-- /abco:{dataset_id} -->",
    ]
    return "\n".join(lines)


def _front_matter_list(card: str, key: str) -> list[str]:
    """The items of a top-level YAML list ``key`` in a card's front matter (block style)."""
    if not card.startswith("---"):
        return []
    items: list[str] = []
    inside = False
    for line in card.split("---", 2)[1].splitlines():
        if not line.strip():
            continue
        if not line.startswith((" ", "-")):
            inside = line.split(":", 1)[0].strip() == key
        elif inside and line.lstrip().startswith("- "):
            items.append(line.lstrip()[2:].strip().strip("'\""))
    return items


def dataset_card(
    dataset_id: str,
    path: str | os.PathLike[str],
    *,
    previous: str | None = None,
    filename: str | None = None,
) -> str:
    """The README.md of the dataset repo, with the section of ``dataset_id`` written in.

    The card has YAML front matter (license, task categories, tags) and one section per dataset,
    built from the file's root attributes; sections of other datasets found in ``previous`` are
    kept, so one repo can hold all the datasets.

    Args:
        dataset_id: The dataset being pushed.
        path: Its HDF5 file.
        previous: The card currently in the repo, if any.
        filename: The file's name in the repo; default the local file's name.

    Returns:
        The card's text.
    """
    file_path = Path(path)
    attrs = _root_attributes(file_path)
    size, sha256 = file_digest(file_path)
    sections: dict[str, str] = {}
    tags = {"abco", "imitation-learning", "imitation-from-observation", "hdf5"}
    if previous:
        for match in re.finditer(r"<!-- abco:(\S+) -->.*?<!-- /abco:\1 -->", previous, re.S):
            sections[match.group(1)] = match.group(0)
        tags.update(_front_matter_list(previous, "tags"))
    sections[dataset_id] = _card_section(
        dataset_id, filename or file_path.name, size, sha256, attrs
    )
    for key in ("env_id", "kind"):
        if isinstance(attrs.get(key), str):
            tags.add(attrs[key])
    header = [
        "---",
        f"license: {CARD_LICENSE}",
        "task_categories:",
        "- reinforcement-learning",
        "tags:",
        *[f"- {tag}" for tag in sorted(tags)],
        "pretty_name: abco datasets",
        "---",
        "",
        "# abco datasets",
        "",
        "State-only expert demonstrations and random-policy pre-demonstrations for imitation from",
        "observation (ABCO), one HDF5 file per dataset, readable with plain h5py. Load one with",
        "`abco_data.load(id)`; every file is checked against the sha256 in abco's manifest.",
        "",
    ]
    return "\n".join(header + [sections[key] + "\n" for key in sorted(sections)])


def push(
    dataset_id: str,
    repo_id: str,
    *,
    path: str | os.PathLike[str] | None = None,
    revision: str | None = None,
    token: str | None = None,
    create_repo: bool = True,
    manifest: Manifest | str | os.PathLike[str] | None = None,
) -> str:
    """Upload a dataset file and its dataset card to a Hub dataset repo (for maintainers).

    Both go in one commit: the file under its manifest filename (or ``<name>.hdf5``) and README.md
    with this dataset's section added to the card already in the repo.

    Args:
        dataset_id: The dataset id.
        repo_id: The dataset repo, ``owner/name``.
        path: The file to upload; default the abco cache's copy.
        revision: Branch to commit to; default ``main``.
        token: Hub token; default the logged-in one.
        create_repo: Create the repo if it does not exist.
        manifest: A manifest or the path of one; a file listed there must match its entry.

    Returns:
        The commit id.

    Raises:
        UnknownDatasetError: Unknown id.
        DatasetNotAvailableError: No file at ``path`` (or in the cache).
        ChecksumError: The file differs from the manifest's entry for the id.
    """
    from huggingface_hub import CommitOperationAdd, HfApi, hf_hub_download

    man = _as_manifest(manifest)
    cached = cached_path(dataset_id, manifest=man)
    file_path = Path(path).expanduser() if path is not None else cached
    if not file_path.is_file():
        raise DatasetNotAvailableError(
            f"no file to push for {dataset_id} at {file_path} (generate it first)"
        )
    entry = man.entry(dataset_id)
    if entry is not None:
        verify_file(file_path, entry, dataset_id=dataset_id, what="file to push")
    filename = _filename(dataset_id, man)

    endpoint = _hf_endpoint()
    api = HfApi(endpoint=endpoint, token=token)
    if create_repo:
        api.create_repo(repo_id, repo_type="dataset", exist_ok=True, token=token)
    previous = None
    try:
        readme = hf_hub_download(
            repo_id,
            "README.md",
            repo_type="dataset",
            revision=revision,
            token=token,
            endpoint=endpoint,
            cache_dir=_hf_cache_dir(),
            force_download=True,
        )
        previous = Path(readme).read_text(encoding="utf-8")
    except _transfer_errors() as err:
        logger.info("no dataset card in %s yet (%s): writing a new one", repo_id, err)
    card = dataset_card(dataset_id, file_path, previous=previous, filename=filename)
    operations = [
        CommitOperationAdd(path_in_repo=filename, path_or_fileobj=str(file_path)),
        CommitOperationAdd(path_in_repo="README.md", path_or_fileobj=card.encode("utf-8")),
    ]
    size, sha256 = file_digest(file_path)
    info = api.create_commit(
        repo_id,
        operations,
        commit_message=f"Add {dataset_id} ({filename}, sha256 {sha256[:12]})",
        commit_description=f"{filename}: {size} bytes, sha256 {sha256}",
        repo_type="dataset",
        revision=revision,
        token=token,
    )
    commit = str(info.oid)
    if not _HEX40.fullmatch(commit):
        logger.warning("the Hub returned an unexpected commit id %r", commit)
    logger.info("pushed %s to %s at commit %s", dataset_id, repo_id, commit)
    return commit

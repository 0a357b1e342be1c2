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

The manifest and the checks against it live in :mod:`abco_data.manifest`; uploading (for
maintainers) in :mod:`abco_data.publish`.

Example:
    >>> from abco_data.hub import cached_path
    >>> cached_path("abco/maze5x5-expert-v0", cache_dir="/data/abco").parent.as_posix()
    '/data/abco'
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from abco_data.errors import ChecksumError, DatasetNotAvailableError
from abco_data.manifest import (
    DEFAULT_REPO_ID,
    Manifest,
    ManifestEntry,
    _as_manifest,
    _install,
    _temporary_name,
    cached_path,
    default_cache_dir,
    file_digest,
    known_ids,
    read_manifest,
    verify_file,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from abco_data import Dataset

__all__ = [
    "DEFAULT_REPO_ID",
    "Manifest",
    "ManifestEntry",
    "cached_path",
    "default_cache_dir",
    "download",
    "fetch",
    "file_digest",
    "known_ids",
    "load",
    "read_manifest",
    "verify_file",
]

logger = logging.getLogger(__name__)


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

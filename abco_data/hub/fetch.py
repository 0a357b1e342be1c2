"""Getting a dataset: the local cache, then the Hugging Face Hub, then local generation.

:func:`load` looks for a dataset in three places, in order:

1. the abco cache (``$ABCO_DATA_HOME`` or ``~/.cache/abco/datasets``): a file found there is
   checked (size and sha256) against the manifest shipped in the package; one that fails is
   reported in a log warning naming the file and both digests, and replaced, never used. An
   id the manifest does not list has nothing to check a cached copy against: it is generated
   afresh (step 3) every time;
2. the Hugging Face Hub: the file is fetched with :func:`huggingface_hub.hf_hub_download` from the
   dataset repo at the revision the manifest pins (through the huggingface_hub cache, so an
   interrupted download resumes), checked against the manifest, and moved into the abco cache
   atomically (where the abco cache is full or read-only, the checked copy in the
   huggingface_hub cache is used in place; a bad copy there is removed, but never a file a
   link of that cache points to outside it);
3. local generation with :func:`abco_data.generate`, whose bytes equal the published ones, so the
   same manifest entry checks them.

Every call to the Hub has a total time limit, ``$ABCO_HUB_TIMEOUT`` seconds (default 60),
connection, answers and huggingface_hub's retries included, and may not receive more bytes
than the manifest's size of the file (:mod:`abco_data.hub.calls`): a Hub that never answers,
drips its answer or announces a file far larger than the manifest's counts as any other Hub
failure, and :func:`load` generates the dataset instead. huggingface_hub's retry warnings are
held back; the failure is reported once, in one line.

Temporary files that killed runs left in the cache are removed on the next call. A cache
folder that cannot be written ends in a :class:`~abco_data.errors.DatasetWriteError` naming
it; a cache file that is not a regular file (a FIFO, a device, a folder, a symbolic link) is
never replaced: :class:`~abco_data.errors.InvalidTargetError`.

Offline (``offline=True``, or huggingface_hub's offline mode: ``HF_HUB_OFFLINE=1``) no request
is sent: a copy already in the huggingface_hub cache is still used, and otherwise the dataset is
generated. The Hub endpoint, the huggingface_hub cache, offline mode and progress bars are
huggingface_hub's own settings (:mod:`huggingface_hub.constants`: ``HF_ENDPOINT``,
``HF_HOME``/``HF_HUB_CACHE``, ``HF_HUB_OFFLINE``, ``HF_HUB_DISABLE_PROGRESS_BARS``, read when
huggingface_hub is imported); abco_data passes none of them itself. Nothing half-written ever
has a cache file's name: every file is written under a hidden temporary name in the cache
folder and renamed with :func:`os.replace` once verified.

The manifest and the checks against it live in :mod:`abco_data.hub.manifest`; uploading (for
maintainers) in :mod:`abco_data.hub.publish`.

Example:
    >>> from abco_data.hub.fetch import cached_path
    >>> cached_path("abco/maze5x5-expert-v0", cache_dir="/data/abco").parent.as_posix()
    '/data/abco'
"""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path

from huggingface_hub import constants, hf_hub_download, try_to_load_from_cache
from huggingface_hub.errors import EntryNotFoundError, HfHubHTTPError, OfflineModeIsEnabled
from huggingface_hub.utils import httpx, silent_tqdm

from abco_data.dataset import Dataset, open_dataset
from abco_data.errors import (
    ChecksumError,
    DatasetNotAvailableError,
    DatasetWriteError,
    WrongKindError,
)
from abco_data.format.files import (
    atomic_target,
    check_target,
    file_digest,
    remove_path,
    remove_stale_temporaries,
)
from abco_data.generation.generate import generate
from abco_data.hub.calls import HubCallStopped, call_hub, hub_timeout
from abco_data.hub.fetch_lock import acquire_fetch_lock
from abco_data.hub.manifest import (
    CACHE_ENV,
    DEFAULT_REPO_ID,
    Manifest,
    ManifestEntry,
    as_manifest,
    cached_path,
    default_cache_dir,
    install_verified,
    known_ids,
    read_manifest,
    verify_file,
)
from abco_data.progress import log_progress_class
from abco_data.registry import check_layout_count, spec
from abco_data.user.datasets import load_user_dataset
from abco_data.user.ids import is_user_id

__all__ = [
    "DEFAULT_REPO_ID",
    "HUB_ERRORS",
    "Manifest",
    "ManifestEntry",
    "cached_path",
    "default_cache_dir",
    "download",
    "fetch",
    "file_digest",
    "hub_location",
    "known_ids",
    "load",
    "read_manifest",
    "verify_file",
]

logger = logging.getLogger(__name__)

#: What huggingface_hub raises when it cannot give us a file (not programming errors): HTTP
#: errors, a file the repo or the cache lacks, offline mode, a transfer its retries could not
#: finish (its HTTP client's errors, which it re-exports as ``huggingface_hub.utils.httpx``)
#: and OS-level failures.
HUB_ERRORS: tuple[type[BaseException], ...] = (
    HfHubHTTPError, EntryNotFoundError, OfflineModeIsEnabled, httpx.HTTPError, OSError)


def _is_offline(offline: bool | None) -> bool:
    """``offline`` if given, else huggingface_hub's offline mode (``HF_HUB_OFFLINE``)."""
    return bool(offline) if offline is not None else constants.is_offline_mode()


def hub_location(manifest: Manifest, revision: str | None) -> str:
    """The dataset repo at ``revision`` on huggingface_hub's endpoint, for messages."""
    return f"{constants.ENDPOINT}/datasets/{manifest.repo_id}@{revision}"


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
    rev = revision or manifest.revision
    if not rev:
        raise DatasetNotAvailableError(
            f"{dataset_id} is not published: the manifest {manifest.path} pins no Hub revision"
        )
    limit = hub_timeout()  # a bad $ABCO_HUB_TIMEOUT is reported, not taken for a Hub failure
    # Endpoint and cache are huggingface_hub's own; silent_tqdm is the do-nothing bar it
    # passes itself where it wants no progress shown (its annotation of tqdm_class asks for a
    # tqdm subclass, which silent_tqdm is not: hence the ignore).
    bar = log_progress_class() if progress else silent_tqdm
    try:
        local = call_hub(lambda: hf_hub_download(  # pyright: ignore[reportCallIssue]
            repo_id=manifest.repo_id,
            filename=entry.filename,
            repo_type="dataset",
            revision=rev,
            local_files_only=local_files_only,
            force_download=force_download,
            tqdm_class=bar,  # pyright: ignore[reportArgumentType]
        ), timeout=limit, max_bytes=entry.size)
    except (*HUB_ERRORS, ValueError) as err:  # ValueError: huggingface_hub's "too large"
        if local_files_only:
            reason = "offline and not in the huggingface_hub cache"
        elif isinstance(err, HubCallStopped):
            reason = str(err)
        else:
            reason = f"{type(err).__name__}: {str(err).strip().splitlines()[0] if str(err) else ''}"
        raise DatasetNotAvailableError(
            f"could not get {entry.filename} ({dataset_id}) from the Hub at"
            f" {hub_location(manifest, rev)}: {reason}"
        ) from err
    return Path(local)


def _evict_hub_copy(path: Path) -> None:
    """Remove a bad file from the huggingface_hub cache: its snapshot link, and the blob the
    link points to when that blob is in the huggingface_hub cache (never a file elsewhere)."""
    cache = Path(constants.HF_HUB_CACHE).resolve()
    link, blob = Path(os.path.abspath(path)), Path(os.path.realpath(path))
    for item in (link, blob):
        if item.is_relative_to(cache):
            remove_path(item)
        else:
            logger.warning("not removing %s: it is outside the huggingface_hub cache %s",
                           item, cache)


def _in_hub_cache(entry: ManifestEntry, manifest: Manifest, rev: str) -> bool:
    """Whether the huggingface_hub cache already holds the file at ``rev``."""
    found = try_to_load_from_cache(
        repo_id=manifest.repo_id,
        filename=entry.filename,
        revision=rev,
        repo_type="dataset",
    )
    return isinstance(found, str)


def _cache_error(err: OSError, target: Path) -> DatasetWriteError:
    return DatasetWriteError(
        err.errno or errno.EIO, f"cannot write {target.name} into the dataset cache"
        f" {target.parent}: {err.strerror or err} (set {CACHE_ENV} to a writable folder)",
        str(target.parent))


def _install_or_use(hub_path: Path, target: Path, entry: ManifestEntry,
                    dataset_id: str) -> Path:
    """The verified Hub copy installed at ``target``; where the abco cache cannot take it
    (full, read-only), the verified copy in the huggingface_hub cache itself."""
    try:
        return install_verified(hub_path, target, entry, dataset_id, "downloaded file")
    except ChecksumError:
        raise
    except OSError as err:
        verify_file(hub_path, entry, dataset_id=dataset_id, what="downloaded file")
        logger.warning("%s; using the verified copy in the huggingface_hub cache, %s",
                       _cache_error(err, target), hub_path)
        return hub_path


def _download_into(dataset_id: str, entry: ManifestEntry, manifest: Manifest, target: Path, *,
                   revision: str | None, progress: bool, offline: bool) -> Path:
    """Hub (or huggingface_hub cache) -> verified -> ``target``, atomically."""
    rev = revision or manifest.revision
    had_copy = bool(rev) and _in_hub_cache(entry, manifest, rev or "")
    hub_path = _hub_file(
        dataset_id, entry, manifest, revision=revision, progress=progress, local_files_only=offline
    )
    try:
        return _install_or_use(hub_path, target, entry, dataset_id)
    except ChecksumError as err:
        logger.warning("%s; removing it from the huggingface_hub cache", err)
        _evict_hub_copy(hub_path)
        if offline or not had_copy:
            raise
    # The bad copy was an old one from the huggingface_hub cache: fetch it again, once.
    hub_path = _hub_file(dataset_id, entry, manifest, revision=revision, progress=progress,
                         local_files_only=False, force_download=True)
    try:
        return _install_or_use(hub_path, target, entry, dataset_id)
    except ChecksumError:
        _evict_hub_copy(hub_path)
        raise


def _generate_into(dataset_id: str, entry: ManifestEntry | None, target: Path, *,
                   progress: bool) -> Path:
    """Generate ``dataset_id`` locally, check it against ``entry``, and move it to ``target``.

    Without an entry the file just generated is the reference (generation is deterministic):
    it replaces whatever the cache held, which is never used unchecked.
    """
    try:
        with atomic_target(target, "generating") as tmp:
            generate(dataset_id, tmp, progress=progress)
            if entry is not None:
                verify_file(tmp, entry, dataset_id=dataset_id, what="locally generated file",
                            shown_as=target)
    except DatasetWriteError:
        raise
    except OSError as err:
        raise _cache_error(err, target) from err
    logger.info("generated %s into %s", dataset_id, target)
    return target


def _cached_copy(target: Path, entry: ManifestEntry, dataset_id: str) -> Path | None:
    """``target`` if the cache holds a good copy there; None (logged) if not."""
    if not target.exists():
        return None
    try:
        verify_file(target, entry, dataset_id=dataset_id, what="cached file")
    except ChecksumError as err:
        logger.warning("%s; it will be replaced", err)
        return None
    except OSError as err:
        logger.warning("cannot read the cached file %s (%s); it will be replaced", target, err)
        return None
    return target


# --------------------------------------------------------------------------- public API


def fetch(dataset_id: str, *, cache_dir: str | os.PathLike[str] | None = None,
          revision: str | None = None, offline: bool | None = None, progress: bool = True,
          manifest: Manifest | str | os.PathLike[str] | None = None) -> Path:
    """Make sure the abco cache holds a verified copy of ``dataset_id`` and return its path.

    Same arguments and order of sources as :func:`load`, which opens the returned file.

    Raises:
        UnknownDatasetError: Unknown id.
        ChecksumError: The locally generated file differs from the manifest entry.
        DatasetNotAvailableError: No source could provide the dataset.
        DatasetWriteError: The cache cannot be written (full, read-only, not a folder).
        InvalidTargetError: The cache holds something else than a regular file under the
            dataset's name (a FIFO, a device, a folder, a symbolic link).
        InvalidParameterError: ``$ABCO_HUB_TIMEOUT`` is not a number of seconds in range.
    """
    man = as_manifest(manifest)
    target = cached_path(dataset_id, cache_dir, manifest=man)
    with acquire_fetch_lock(target, dataset_id, _cache_error):  # one fetch at a time
        return _fetch(dataset_id, man, target, revision, offline, progress)


def _fetch(dataset_id: str, man: Manifest, target: Path, revision: str | None,
           offline: bool | None, progress: bool) -> Path:  # fmt: skip
    entry = man.entry(dataset_id)
    remove_stale_temporaries(target.parent)  # left by killed downloads and generations
    if entry is None:
        logger.info("the manifest has no entry for %s, so nothing to check a cached copy"
                    " against: generating it", dataset_id)
        return _generate_into(dataset_id, None, target, progress=progress)
    if _cached_copy(target, entry, dataset_id) is not None:
        return target
    check_target(target)  # a FIFO, device, folder or link in the cache: refused, never replaced

    try:
        return _download_into(dataset_id, entry, man, target, revision=revision,
                              progress=progress, offline=_is_offline(offline))
    except (DatasetNotAvailableError, ChecksumError) as err:
        logger.warning("%s; generating %s locally instead", err, dataset_id)
    return _generate_into(dataset_id, entry, target, progress=progress)


def load(dataset_id: str, *, cache_dir: str | os.PathLike[str] | None = None,
         revision: str | None = None, offline: bool | None = None, progress: bool = True,
         manifest: Manifest | str | os.PathLike[str] | None = None,
         layouts: int | None = None) -> Dataset:
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
        layouts: Maze datasets: keep the episodes of the first ``layouts`` layouts only
            (:meth:`~abco_data.Dataset.first_layouts`); the whole file is fetched and checked.

    A user dataset id (``local/NAME-v0``) opens its registered file once checked against the
    user manifest of ``cache_dir`` (:func:`abco_data.user.datasets.load_user_dataset`).

    Returns:
        The opened dataset (:func:`abco_data.open_dataset` of the cached file).

    Raises:
        UnknownDatasetError: Unknown id (the message lists the known ones).
        ChecksumError: The locally generated file differs from the manifest entry.
        DatasetNotAvailableError: No source could provide the dataset.
        ValueError: ``layouts`` is not an integer from 1 to the dataset's layouts (checked
            against the registry before anything is fetched, then against the file).
        WrongKindError: ``layouts`` for a dataset without maze layouts.
        InvalidParameterError: ``$ABCO_HUB_TIMEOUT`` is not a number of seconds in range.
        InvalidTargetError: The cache holds something else than a regular file under the
            dataset's name (a FIFO, a device, a folder, a symbolic link).
    """
    if is_user_id(dataset_id):  # the user's own: its registered file, checked
        return load_user_dataset(dataset_id, cache_dir, layouts=layouts)
    if layouts is not None:  # a bad count fails now, not after minutes of generation
        wanted = spec(dataset_id)
        if not wanted.is_maze:
            raise WrongKindError(f"{dataset_id} holds {wanted.env_id} data, which has no maze"
                                 f" layouts to take the first {layouts!r} of")
        check_layout_count(layouts, wanted.params["layouts"], f"layouts={layouts!r}",
                           dataset_id)
    ds = open_dataset(fetch(dataset_id, cache_dir=cache_dir, revision=revision,
                            offline=offline, progress=progress, manifest=manifest))
    return ds if layouts is None else ds.first_layouts(layouts)


def download(dataset_id: str, *, cache_dir: str | os.PathLike[str] | None = None,
             revision: str | None = None, progress: bool = True,
             manifest: Manifest | str | os.PathLike[str] | None = None) -> Path:
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
        InvalidTargetError: The cache holds something else than a regular file under the
            dataset's name.
    """
    man = as_manifest(manifest)
    target = cached_path(dataset_id, cache_dir, manifest=man)
    entry = man.entry(dataset_id)
    if entry is None:
        raise DatasetNotAvailableError(
            f"{dataset_id} has no published file: the manifest {man.path} has no entry for it "
            "(generate it locally with abco_data.generate or abco_data.load)"
        )
    check_target(target)
    return _download_into(dataset_id, entry, man, target, revision=revision, progress=progress,
                          offline=_is_offline(None))

"""Publishing datasets to the Hugging Face Hub (maintainers): the file and its dataset card."""

from __future__ import annotations

import json
import logging
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from huggingface_hub import CommitOperationAdd, HfApi, hf_hub_download

from abco_data.errors import DatasetError, DatasetNotAvailableError
from abco_data.format import attr_value, open_h5
from abco_data.format.files import file_digest
from abco_data.hub.calls import call_hub
from abco_data.hub.fetch import HUB_ERRORS
from abco_data.hub.manifest import (
    Manifest,
    as_manifest,
    cache_filename,
    cached_path,
    check_repo_id,
    verify_file,
)

__all__ = ["push", "dataset_card", "CARD_LICENSE"]

logger = logging.getLogger(__name__)

#: License written into the dataset card.
CARD_LICENSE = "mit"
_HEX40 = re.compile(r"[0-9a-f]{40}")


@contextmanager
def _hub_errors(what: str) -> Iterator[None]:
    """The Hub refusing or failing a request becomes one clear line."""
    try:
        yield
    except HUB_ERRORS as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise DatasetError(f"{what}: {first}") from err


def _root_attributes(path: Path) -> dict[str, Any]:
    with open_h5(path) as handle:
        return {key: attr_value(handle.attrs[key]) for key in sorted(handle.attrs)}


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


def push(dataset_id: str, repo_id: str, *, path: str | os.PathLike[str] | None = None,
         revision: str | None = None, token: str | None = None, create_repo: bool = True,
         manifest: Manifest | str | os.PathLike[str] | None = None) -> str:
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

    Every request has the total time limit of ``$ABCO_HUB_TIMEOUT`` (see
    :mod:`abco_data.hub.calls`); set it higher to upload a large file on a slow line.

    Returns:
        The commit id.

    Raises:
        InvalidParameterError: ``repo_id`` is not a valid ``owner/name`` Hub repo id.
        UnknownDatasetError: Unknown id.
        DatasetNotAvailableError: No file at ``path`` (or in the cache).
        ChecksumError: The file differs from the manifest's entry for the id.
        DatasetError: The Hub refused or failed a request (the message says which).
    """
    check_repo_id(repo_id)
    man = as_manifest(manifest)
    cached = cached_path(dataset_id, manifest=man)
    file_path = Path(path).expanduser() if path is not None else cached
    if not file_path.is_file():
        raise DatasetNotAvailableError(
            f"no file to push for {dataset_id} at {file_path} (generate it first)"
        )
    entry = man.entry(dataset_id)
    if entry is not None:
        verify_file(file_path, entry, dataset_id=dataset_id, what="file to push")
    filename = cache_filename(dataset_id, man)

    api = HfApi(token=token)  # huggingface_hub's own endpoint (HF_ENDPOINT)
    if create_repo:
        with _hub_errors(f"could not create the dataset repo {repo_id}"):
            call_hub(lambda: api.create_repo(repo_id, repo_type="dataset", exist_ok=True,
                                             token=token))
    previous = None
    try:
        readme = call_hub(lambda: hf_hub_download(
            repo_id,
            "README.md",
            repo_type="dataset",
            revision=revision,
            token=token,
            force_download=True,
        ))
        previous = Path(readme).read_text(encoding="utf-8")
    except HUB_ERRORS as err:
        logger.info("no dataset card in %s yet (%s): writing a new one", repo_id, err)
    card = dataset_card(dataset_id, file_path, previous=previous, filename=filename)
    operations = [
        CommitOperationAdd(path_in_repo=filename, path_or_fileobj=str(file_path)),
        CommitOperationAdd(path_in_repo="README.md", path_or_fileobj=card.encode("utf-8")),
    ]
    size, sha256 = file_digest(file_path)
    with _hub_errors(f"could not push {dataset_id} to {repo_id}"):
        info = call_hub(lambda: api.create_commit(
            repo_id,
            operations,
            commit_message=f"Add {dataset_id} ({filename}, sha256 {sha256[:12]})",
            commit_description=f"{filename}: {size} bytes, sha256 {sha256}",
            repo_type="dataset",
            revision=revision,
            token=token,
        ))
    commit = str(info.oid)
    if not _HEX40.fullmatch(commit):
        logger.warning("the Hub returned an unexpected commit id %r", commit)
    logger.info("pushed %s to %s at commit %s", dataset_id, repo_id, commit)
    return commit

"""The size and sha256 a dataset file must have, whatever the file says about itself.

Generation is deterministic, so every file abco writes has known bytes:

- a published dataset (root attribute ``overrides`` is ``[]``) has the bytes of its manifest
  entry, or, for an id the manifest does not list, the bytes the generator writes for it;
- a variant (``overrides`` names the creation parameters changed) has the bytes the generator
  writes with those parameters, which :func:`expected_digest` reproduces (once per process).

A file whose attributes were edited to dodge the check (``overrides`` rewritten, say) then
fails it as surely as any other change: its bytes are not the ones its claims reproduce.

Example:
    >>> import tempfile, os, abco_data
    >>> path = abco_data.generate("abco/cartpole-expert-v0", os.path.join(tempfile.mkdtemp(),
    ...     "c.hdf5"), progress=False, episodes=1, reference_episodes=1,
    ...     reference_expert_episodes=1)
    >>> expected = expected_digest(abco_data.open_dataset(path))
    >>> expected.source.startswith("the bytes abco generates for abco/cartpole-expert-v0 with")
    True
    >>> check_checksum(path, expected)
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from abco_data.dataset import Dataset
from abco_data.errors import ChecksumError, CorruptDatasetError
from abco_data.format.files import file_digest
from abco_data.generation.generate import GENERATOR, GENERATOR_VERSION, generate
from abco_data.hub.manifest import Manifest, as_manifest
from abco_data.registry import DATASET_IDS, spec
from abco_data.user.datasets import user_entry
from abco_data.user.ids import is_user_id

__all__ = ["ExpectedDigest", "expected_digest", "check_checksum", "claimed_overrides"]

#: Digests of reproduced variants: (id, overrides as JSON) -> (size, sha256).
_REPRODUCED: dict[tuple[str, str], tuple[int, str]] = {}


@dataclass(frozen=True)
class ExpectedDigest:
    """What a file must be.

    Attributes:
        size: Size in bytes.
        sha256: Lower-case hex sha256.
        source: Where the expectation comes from, for messages.
    """

    size: int
    sha256: str
    source: str


def claimed_overrides(ds: Dataset) -> dict[str, Any]:
    """The creation parameters the file says were changed, with their values.

    Raises:
        CorruptDatasetError: ``overrides`` or ``creation_params`` are not what the generator
            writes, or name a parameter the dataset does not have or a value out of range.
    """
    try:
        names = json.loads(ds.attrs.get("overrides", "[]"))
        params = json.loads(ds.attrs["creation_params"])
    except (TypeError, ValueError) as err:  # the file's JSON only
        raise CorruptDatasetError(f"{ds.path}: unreadable overrides or creation_params:"
                                  f" {err}") from err
    if not isinstance(names, list) or not isinstance(params, dict) \
            or not all(isinstance(n, str) and n in params for n in names):
        raise CorruptDatasetError(f"{ds.path}: overrides {names!r} do not name creation"
                                  " parameters")
    if ds.id not in DATASET_IDS:
        return {n: params[n] for n in names}
    defaults = spec(ds.id).params
    out = {}
    for name in names:
        value, default = params[name], defaults.get(name)
        if name == "hold":  # any hold costs the same to reproduce: only its shape is checked
            from abco_envs.experts.random_policy import hold_range

            try:
                hold_range(value)
            except ValueError:
                raise CorruptDatasetError(f"{ds.path}: creation parameter hold={value!r} is"
                                          f" not a valid variant of {ds.id}") from None
            out[name] = value
            continue
        same_type = type(value) is type(default)
        # A variant is never bigger than the published dataset: reproducing one costs at
        # most as much as generating the published one (the seed may be any integer).
        in_range = name == "seed" or isinstance(value, bool) or (
            isinstance(value, int) and isinstance(default, int) and 0 <= value <= default)
        if not (same_type and in_range):
            raise CorruptDatasetError(f"{ds.path}: creation parameter {name}={value!r} is not"
                                      f" a valid variant of {ds.id}")
        out[name] = value
    return out


def _reproduce(dataset_id: str, overrides: dict[str, Any]) -> tuple[int, str]:
    key = (dataset_id, json.dumps(overrides, sort_keys=True))
    if key not in _REPRODUCED:
        with tempfile.TemporaryDirectory(prefix="abco-reproduce-") as tmp:
            path = generate(dataset_id, Path(tmp) / "reproduced.hdf5", progress=False,
                            **overrides)
            _REPRODUCED[key] = file_digest(path)
    return _REPRODUCED[key]


def expected_digest(ds: Dataset, *,
                    manifest: Manifest | str | os.PathLike[str] | None = None
                    ) -> ExpectedDigest | None:
    """The digest ``ds``'s file must have (see the module docstring), or None when no
    checksum can be known: an id neither the manifest, this abco's registry nor the user
    manifest (:mod:`abco_data.user.datasets`: a registered user dataset) knows.

    Raises:
        CorruptDatasetError: Unreadable claims (see :func:`claimed_overrides`).
        ChecksumError: A variant made by another generator, which this abco cannot reproduce.
    """
    overrides = claimed_overrides(ds)
    entry = as_manifest(manifest).entry(ds.id)
    if not overrides and entry is not None:
        return ExpectedDigest(entry.size, entry.sha256, f"the manifest entry of {ds.id}")
    if ds.id not in DATASET_IDS:
        user = user_entry(ds.id) if is_user_id(ds.id) else None
        return None if user is None else ExpectedDigest(
            user.size, user.sha256, f"the user manifest entry of {ds.id}")
    made_by = (ds.attrs.get("generator"), ds.attrs.get("generator_version"))
    if made_by != (GENERATOR, GENERATOR_VERSION):
        raise ChecksumError(f"{ds.path}: made by generator {made_by[0]!r} version"
                            f" {made_by[1]!r}; this abco reproduces only {GENERATOR} version"
                            f" {GENERATOR_VERSION}, so it cannot check the file's bytes")
    size, sha256 = _reproduce(ds.id, overrides)
    with_params = ", ".join(f"{k}={v}" for k, v in sorted(overrides.items()))
    return ExpectedDigest(size, sha256, f"the bytes abco generates for {ds.id}"
                          + (f" with {with_params}" if with_params else ""))


def check_checksum(path: str | os.PathLike[str], expected: ExpectedDigest) -> None:
    """Raise :class:`ChecksumError` unless the file at ``path`` is what ``expected`` says."""
    size, sha256 = file_digest(path)
    if (size, sha256) != (expected.size, expected.sha256):
        raise ChecksumError(f"{path}: {size} bytes with sha256 {sha256}; expected"
                            f" {expected.size} bytes with sha256 {expected.sha256} ("
                            f"{expected.source})")

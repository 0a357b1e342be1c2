"""Dataset ids of the user's own datasets: ``NAMESPACE/NAME-vN`` outside abco's namespace.

abco's datasets live in namespace ``abco`` (``abco/cartpole-expert-v0``). A dataset a user
records (:func:`abco_data.record`) or imports from Minari (:func:`abco_data.import_minari`)
takes an id of a namespace of its own, such as ``local/cartpole-mine-v0``: a namespace and a
name of letters, digits, ``_`` and ``-`` (the name also ``.``), and a version ``-vN`` that the
user changes whenever the bytes would. Namespace ``abco`` is reserved (in any case), and so is
every id the shipped manifest lists, so a user id never shadows a built-in one. Readers accept
a file holding a user id; :mod:`abco_data.user.datasets` keeps the registered ones' bytes.

Example:
    >>> is_user_id("local/cartpole-mine-v0"), is_user_id("abco/cartpole-expert-v0")
    (True, False)
    >>> check_user_id("abco/cartpole-mine-v0")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    abco_data.errors.InvalidParameterError: ... namespace 'abco' is abco's own ...
    >>> user_id_for_file("runs/my cartpole.hdf5")
    'local/my-cartpole-v0'
"""

from __future__ import annotations

import os
import re
from pathlib import PurePath

from abco_data.errors import InvalidParameterError
from abco_data.hub.manifest import read_manifest
from abco_data.registry import DATASET_IDS

__all__ = ["USER_NAMESPACE", "RESERVED_NAMESPACES", "USER_ID_FORM", "is_user_id",
           "check_user_id", "user_id_for_file", "split_user_id"]

#: The namespace of the ids abco derives from file names (``--out`` without ``--id``).
USER_NAMESPACE = "local"
#: Namespaces no user id may take (compared without case).
RESERVED_NAMESPACES = ("abco",)
#: The shape of a user id, for messages.
USER_ID_FORM = "NAMESPACE/NAME-vN (e.g. local/cartpole-mine-v0)"
_USER_ID = re.compile(r"(?P<namespace>[A-Za-z0-9][A-Za-z0-9_-]{0,63})"
                      r"/(?P<name>[A-Za-z0-9][A-Za-z0-9_.-]{0,127}-v[0-9]{1,6})")


def _problem(dataset_id: object) -> str | None:
    """Why ``dataset_id`` is no user id, or None when it is one."""
    if not isinstance(dataset_id, str) or _USER_ID.fullmatch(dataset_id) is None:
        return f"a user dataset id reads {USER_ID_FORM}, got {dataset_id!r}"
    namespace = dataset_id.split("/", 1)[0]
    if namespace.lower() in RESERVED_NAMESPACES:
        return (f"namespace {namespace!r} is abco's own (its built-in datasets); give"
                f" {dataset_id!r} a namespace of your own, e.g. {USER_NAMESPACE}/...")
    if dataset_id in DATASET_IDS or dataset_id in read_manifest().files:
        return f"{dataset_id!r} is a built-in dataset id; choose another for your own dataset"
    return None


def is_user_id(dataset_id: object) -> bool:
    """Whether ``dataset_id`` is a well-formed user id (see the module docstring)."""
    return _problem(dataset_id) is None


def check_user_id(dataset_id: object) -> str:
    """``dataset_id`` if it is a user id.

    Raises:
        InvalidParameterError: A malformed id, one in a reserved namespace, or a built-in id
            (the message says which and how to fix it).
    """
    problem = _problem(dataset_id)
    if problem is not None:
        raise InvalidParameterError(f"invalid user dataset id: {problem}")
    assert isinstance(dataset_id, str)
    return dataset_id


def split_user_id(dataset_id: str) -> tuple[str, str]:
    """``(namespace, NAME-vN)`` of a user id (checked by :func:`check_user_id`)."""
    namespace, name = check_user_id(dataset_id).split("/", 1)
    return namespace, name


def user_id_for_file(path: str | os.PathLike[str]) -> str:
    """The id of a file written without one: ``local/<file stem>``, with ``-v0`` added unless
    the stem ends in a version; characters an id cannot hold become ``-``.

    Raises:
        InvalidParameterError: No id can be made of the file name (name the id yourself).
    """
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", PurePath(path).stem).strip("-._")
    if re.search(r"-v[0-9]{1,6}$", stem) is None:
        stem += "-v0"
    candidate = f"{USER_NAMESPACE}/{stem[-135:].lstrip('-._')}"
    if not is_user_id(candidate):
        raise InvalidParameterError(f"cannot make a dataset id of the file name {path}"
                                    f" ({candidate!r}); give one: {USER_ID_FORM}")
    return candidate

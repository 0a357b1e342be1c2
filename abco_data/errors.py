"""The errors abco_data raises: each names the file or id and the problem."""

from __future__ import annotations

__all__ = [
    "DatasetError",
    "UnknownDatasetError",
    "CorruptDatasetError",
    "FormatVersionError",
    "WrongKindError",
    "ChecksumError",
    "DatasetNotAvailableError",
    "DatasetWriteError",
    "DatasetReadError",
    "DatasetFileNotFoundError",
]


class DatasetError(Exception):
    """Base class of every dataset problem abco_data reports."""


class UnknownDatasetError(DatasetError, KeyError):
    """A dataset id that abco does not know."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class CorruptDatasetError(DatasetError):
    """A file that is not a readable abco dataset (truncated, corrupt, missing columns)."""


class FormatVersionError(DatasetError):
    """A dataset written in a ``format_version`` this abco cannot read."""


class WrongKindError(DatasetError):
    """A dataset of another kind (or for another env) than the one asked for."""


class ChecksumError(DatasetError):
    """A file whose size or sha256 differs from the manifest's."""


class DatasetNotAvailableError(DatasetError):
    """Neither the cache, the Hub nor local generation could provide a dataset."""


class DatasetWriteError(DatasetError, OSError):
    """Writing a dataset failed (a full disk, say); the target was left as it was."""


class DatasetReadError(DatasetError, OSError):
    """A file that cannot be read at all (no permission, a folder, a broken link...)."""


class DatasetFileNotFoundError(DatasetReadError, FileNotFoundError):
    """No file at the path given."""

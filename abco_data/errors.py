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
    "DatasetChangedError",
    "InvalidTargetError",
    "InvalidParameterError",
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


class DatasetChangedError(DatasetError):
    """The file of an opened dataset was replaced or changed on disk since it was opened.

    Raised when a process (a ``DataLoader`` worker, say) opens the file again and finds
    another file under its name: its rows would not match the index read before.
    """

    def __str__(self) -> str:
        # A DataLoader worker's error comes back with the worker's traceback in its message:
        # keep the one line that says what happened.
        text = super().__str__()
        if "Traceback" in text:
            last = text.strip().splitlines()[-1]
            text = last.split(f"{type(self).__name__}: ", 1)[-1]
        return text


class InvalidTargetError(DatasetError, ValueError):
    """An output path abco will not write to: a device, a FIFO, a socket, a folder or a
    symbolic link (abco writes regular files and new paths only); it was left untouched."""


class InvalidParameterError(DatasetError, ValueError):
    """A creation parameter or setting beyond its documented bounds, or of the wrong type;
    refused before any work is done."""

"""abco_data: the datasets of the ABCO paper as verified, deterministic HDF5 files.

Twenty-two datasets (expert states and random-policy pre-demonstrations for seven
environments, the mazes' start-cell pre-demonstrations of the authors' regime, expert and
pre-demonstration sets over the 10,000 procedural layouts of the 5x5 and 10x10 mazes, and
Acrobot pre-demonstrations of held random actions), each
one HDF5 file in the versioned format of ``docs/format.md``. :func:`load` gets one from the
cache, the Hugging Face Hub, or local generation; :func:`open_dataset` reads a file;
:func:`verify` and :func:`check_dataset` check every byte of one. :func:`record` (any
Gymnasium env) and :func:`import_minari` make datasets of the user's own, with ids of their
own (``local/NAME-v0``) that every reader takes as it takes the built-in ones.
``import abco_data`` does not import torch.

Example:
    >>> import abco_data
    >>> len(abco_data.DATASET_IDS)
    26
    >>> abco_data.dataset_id("CartPole-v1", "pre_demonstrations")
    'abco/cartpole-pre-v0'
"""

from abco_data.dataset import Dataset, open_dataset
from abco_data.errors import (
    ChecksumError,
    CorruptDatasetError,
    DatasetChangedError,
    DatasetError,
    DatasetFileNotFoundError,
    DatasetNotAvailableError,
    DatasetReadError,
    DatasetWriteError,
    FormatVersionError,
    InvalidParameterError,
    InvalidTargetError,
    UnknownDatasetError,
    WrongKindError,
)
from abco_data.format import FORMAT_NAME, FORMAT_VERSION
from abco_data.format.arrays import DatasetArrays, Episode
from abco_data.format.files import sha256_of
from abco_data.generation.generate import GENERATOR_VERSION, generate
from abco_data.generation.reference import (
    ReferenceReturns,
    fresh_reference,
    layout_reference,
    protocol_reference,
)
from abco_data.hub.fetch import download, load
from abco_data.hub.manifest import data_home
from abco_data.hub.publish import push
from abco_data.interop.minari_import import import_minari
from abco_data.registry import DATASET_IDS, DatasetSpec, dataset_id, spec
from abco_data.user.ids import is_user_id
from abco_data.user.record import record
from abco_data.verify import VerifyReport, check_dataset, verify

__version__ = "0.1.0"

__all__ = [
    "ChecksumError",
    "CorruptDatasetError",
    "DATASET_IDS",
    "DatasetChangedError",
    "Dataset",
    "DatasetArrays",
    "DatasetError",
    "DatasetFileNotFoundError",
    "DatasetNotAvailableError",
    "DatasetReadError",
    "DatasetSpec",
    "DatasetWriteError",
    "Episode",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "FormatVersionError",
    "GENERATOR_VERSION",
    "InvalidParameterError",
    "InvalidTargetError",
    "ReferenceReturns",
    "UnknownDatasetError",
    "VerifyReport",
    "WrongKindError",
    "check_dataset",
    "data_home",
    "dataset_id",
    "download",
    "fresh_reference",
    "generate",
    "import_minari",
    "is_user_id",
    "layout_reference",
    "protocol_reference",
    "load",
    "open_dataset",
    "push",
    "record",
    "sha256_of",
    "spec",
    "verify",
]

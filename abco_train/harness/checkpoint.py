"""A run's checkpoint: everything needed to resume after an iteration, stored as data.

``checkpoint.pt`` holds the iteration, the method's state (:meth:`Method.state_dict`), its
interaction counts, torch's generator states and the run's config. It is written whole or not
at all (:func:`abco_train.harness.run_folder.write_atomic`) and holds data only: tensors,
numbers, strings, bools, ``None``, and lists, tuples and dicts of them. It is read with
``torch.load(weights_only=True)``, which builds nothing else, so a checkpoint runs no code,
whoever made it. The numpy arrays (and numpy scalars) of a method's state are stored as tagged
tensors of their bytes (:func:`to_saved`) and come back as the same arrays, dtype and shape and
every bit (:func:`from_saved`): a resumed run is the run it would have been. What is read is
checked before use (:func:`load_checkpoint`, :func:`load_method_state`): its keys and types,
an iteration of the run, tensors no larger than the file, a method state that fits the method.

A checkpoint is read into CPU memory whatever device wrote it, and every tensor of the method's
state it restores lands on the device of the tensor it replaces (:func:`place_like`): sampling
indices beside the data they index, networks and optimisers on the run's device. So a CUDA
run resumes on the CPU and a CPU run on CUDA.

A checkpoint of an older abco (a pickle of numpy arrays, or of other objects) is refused with
the command that converts it, ``abco convert-checkpoint RUN_DIR``
(:func:`convert_legacy_checkpoint`), the one place that unpickles; only for run folders you
trust.

Example:
    >>> saved = to_saved({"labels": np.arange(3, dtype=np.int16), "n": np.float32(0.5)})
    >>> type(saved["labels"]).__name__, sorted(saved["labels"])
    ('dict', ['__abco_numpy__', 'bytes', 'scalar', 'shape'])
    >>> back = from_saved(saved)
    >>> back["labels"], back["n"].dtype
    (array([0, 1, 2], dtype=int16), dtype('float32'))
"""

from __future__ import annotations

import io
import math
import os
import pickle
from collections import OrderedDict
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from abco_train.config.run import RunConfig
from abco_train.harness.run_folder import CHECKPOINT, RunFolderError, open_regular, write_atomic
from abco_train.harness.run_lock import run_folder_lock
from abco_train.methods.base import INTERACTION_KINDS, Method

__all__ = ["FORMAT", "LegacyCheckpointError", "save_checkpoint", "load_checkpoint",
           "check_state", "load_method_state", "restore", "to_saved", "from_saved",
           "place_like", "convert_legacy_checkpoint"]  # fmt: skip

#: The checkpoint format: 2 holds data only (1, unversioned, was a pickle).
FORMAT = 2
#: The key that tags a stored numpy array.
NUMPY_TAG = "__abco_numpy__"
#: How deep a checkpoint's containers may nest, and how many values it may hold in all.
MAX_DEPTH, MAX_VALUES = 64, 10_000_000
_LEAVES = (bool, int, float, complex, str, bytes, torch.dtype, torch.device, type(None))
_DTYPE_KINDS = "biufcmMSU"  # numbers, bools, times, strings: never objects (O) nor records (V)


class LegacyCheckpointError(RunFolderError):
    """A checkpoint that holds pickled objects, not just data: an older abco's, or a file
    from elsewhere. Only :func:`convert_legacy_checkpoint` reads it (trusted folders only)."""


def _legacy_message(path: Path) -> str:
    run_dir = path.parent
    return (f"{path} holds pickled Python objects, not just data (a checkpoint of an older "
            "abco, or a file from elsewhere), and is not loaded: loading it could run code. "
            f"Only if you trust {run_dir}, convert it once with `abco convert-checkpoint "
            f"{run_dir}`; else delete it to restart the run")  # fmt: skip


# -- data in, data out -------------------------------------------------------------------------


def to_saved(obj: Any, where: str = "state") -> Any:
    """``obj`` with every numpy array and numpy scalar replaced by a tagged tensor of its bytes
    (containers that hold none are returned as they are).

    Raises:
        TypeError: ``obj`` holds something that is no data (the message says where), such as
            an object of a class of its own or a numpy array of Python objects.
    """
    return _to_saved(obj, where, 0)


def _to_saved(obj: Any, where: str, depth: int) -> Any:
    if depth > MAX_DEPTH:
        raise TypeError(f"{where} nests deeper than {MAX_DEPTH} levels")
    if isinstance(obj, (np.ndarray, np.generic)):
        return _pack(obj, where)
    if type(obj) in (*_LEAVES, torch.Tensor, torch.nn.Parameter, torch.Size):
        return obj  # exact types: a subclass (an enum, say) would be pickled as its class
    if type(obj) in (dict, OrderedDict):
        if NUMPY_TAG in obj:
            raise TypeError(f"{where} has the key {NUMPY_TAG!r}, which checkpoints reserve")
        for key in obj:
            if type(key) not in _LEAVES:
                raise TypeError(f"{where} has a key of type {type(key).__name__}")
        items = {k: _to_saved(v, f"{where}[{k!r}]", depth + 1) for k, v in obj.items()}
        if all(items[k] is v for k, v in obj.items()):
            return obj  # as it is (a module's state dict keeps its version metadata)
        return type(obj)(items)
    if type(obj) in (list, tuple):
        items = [_to_saved(v, f"{where}[{i}]", depth + 1) for i, v in enumerate(obj)]
        return obj if all(a is b for a, b in zip(items, obj)) else type(obj)(items)
    raise TypeError(f"{where} is a {type(obj).__module__}.{type(obj).__qualname__}; a "
                    "checkpoint holds data only (tensors, numpy arrays, numbers, strings, "
                    "None, and lists, tuples and dicts of them)")  # fmt: skip


def _pack(obj: np.ndarray | np.generic, where: str) -> dict[str, Any]:
    array = np.asarray(obj)
    if array.dtype.kind not in _DTYPE_KINDS:
        raise TypeError(f"{where} is a numpy array of dtype {array.dtype}; a checkpoint holds "
                        "arrays of numbers, bools, times and strings")  # fmt: skip
    raw = np.frombuffer(np.ascontiguousarray(array).tobytes(), dtype=np.uint8)
    return {NUMPY_TAG: array.dtype.str, "shape": list(array.shape),
            "scalar": isinstance(obj, np.generic), "bytes": torch.from_numpy(raw.copy())}


def _at(where: str) -> str:
    """``where`` short enough for a one-line message (a crafted key may be long)."""
    return where if len(where) <= 160 else where[:157] + "..."


def from_saved(obj: Any, where: str = "checkpoint") -> Any:
    """``obj`` with every tagged array of :func:`to_saved` back as the numpy array (or scalar)
    it was; every tensor checked to be no larger than the data behind it.

    Raises:
        RunFolderError: A tag that is no array, a tensor larger than its data, or containers
            nested too deeply or holding too many values (the message says where).
    """
    return _from_saved(obj, where, 0, [0])


def _from_saved(obj: Any, where: str, depth: int, seen: list[int]) -> Any:
    seen[0] += 1
    if depth > MAX_DEPTH or seen[0] > MAX_VALUES:
        raise RunFolderError(f"{_at(where)} nests deeper than {MAX_DEPTH} levels or holds more "
                             f"than {MAX_VALUES:,} values")  # fmt: skip
    if isinstance(obj, torch.Tensor):
        _check_tensor(obj, where)
        return obj
    if isinstance(obj, dict):
        if NUMPY_TAG in obj:
            return _unpack(obj, where)
        items = {k: _from_saved(v, f"{where}[{k!r}]", depth + 1, seen) for k, v in obj.items()}
        if all(items[k] is v for k, v in obj.items()):
            return obj
        return type(obj)(items) if type(obj) in (dict, OrderedDict) else items
    if isinstance(obj, (list, tuple)) and not isinstance(obj, torch.Size):
        items = [_from_saved(v, f"{where}[{i}]", depth + 1, seen) for i, v in enumerate(obj)]
        return obj if all(a is b for a, b in zip(items, obj)) else type(obj)(items)
    return obj


def _check_tensor(tensor: torch.Tensor, where: str) -> None:
    """Refuse a tensor whose elements outnumber its storage's (a stride-0 view made to look
    huge: it would become that large the first time it is copied)."""
    needed = tensor.numel() * tensor.element_size()
    if needed > tensor.untyped_storage().nbytes():
        raise RunFolderError(f"{_at(where)} is a tensor of {tuple(tensor.shape)} over "
                             f"{tensor.untyped_storage().nbytes():,} bytes of data")  # fmt: skip


def _unpack(tag: dict[str, Any], where: str) -> np.ndarray | np.generic:
    bad = RunFolderError(f"{_at(where)} is no stored numpy array")
    raw, shape, scalar, name = tag.get("bytes"), tag.get("shape"), tag.get("scalar"), tag[NUMPY_TAG]
    if (set(tag) != {NUMPY_TAG, "shape", "scalar", "bytes"} or not isinstance(name, str)
            or len(name) > 64 or not isinstance(raw, torch.Tensor) or not isinstance(shape, list)
            or len(shape) > 32 or not all(type(n) is int and n >= 0 for n in shape)
            or type(scalar) is not bool or (scalar and shape)):  # fmt: skip
        raise bad
    try:
        dtype = np.dtype(name)
    except (TypeError, ValueError):
        raise bad from None
    if (dtype.kind not in _DTYPE_KINDS or raw.dtype != torch.uint8 or raw.dim() != 1
            or not raw.is_contiguous() or raw.numel() != math.prod(shape) * dtype.itemsize):
        raise bad
    _check_tensor(raw, where)
    array = np.frombuffer(raw.cpu().numpy().tobytes(), dtype=dtype).reshape(shape).copy()
    return array[()] if scalar else array


# -- saving and loading ------------------------------------------------------------------------


def save_checkpoint(path: Path, iteration: int, method: Method, cfg: RunConfig) -> None:
    """Write the state after ``iteration`` to ``path``, as data.

    Raises:
        TypeError: The method's :meth:`~Method.state_dict` holds something that is no data.
        OSError: The write failed (``path`` keeps the previous checkpoint).
    """
    payload = {"format": FORMAT, "iteration": iteration,
               "method": to_saved(method.state_dict(), f"{type(method).__name__}.state_dict()"),
               "interactions": dict(method.interactions),
               "torch_rng": torch.get_rng_state(), "config": to_saved(asdict(cfg), "config"),
               "cuda_rng": torch.cuda.get_rng_state_all() if cfg.device.startswith("cuda")
               else None}  # fmt: skip
    _write(path, payload)


def _write(path: Path, payload: dict[str, Any]) -> None:
    """Serialise in memory, then write through Python's files: a full disk is an ``OSError``
    naming the file (torch's own writer reports it as a ``RuntimeError``)."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    write_atomic(path, lambda tmp: tmp.write_bytes(buffer.getbuffer()))


def load_checkpoint(path: Path) -> dict[str, Any] | None:
    """The checkpoint's state in CPU memory (whatever device wrote it), ``None`` without one.

    Its structure is checked (:func:`check_state`); the iteration against the run's by
    :func:`load_method_state`.

    Raises:
        RunFolderError: The checkpoint is damaged (e.g. truncated), not abco's, holds more
            than data (an older abco's: the message names the command that converts it), or
            is no regular file.
        OSError: It cannot be read.
    """
    if not os.path.lexists(path):
        return None
    with open_regular(path) as handle:
        raw = handle.read()  # read errors are the disk's; what follows, the file's
    return check_state(from_saved(_safe_load(raw, path), str(path)), path)


def _safe_load(raw: bytes, path: Path) -> Any:
    """``torch.load(weights_only=True)`` of a checkpoint's bytes: data only, never code.

    Raises:
        LegacyCheckpointError: It holds pickled objects (names classes or functions).
        RunFolderError: It is damaged.
    """
    try:
        return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        if "GLOBAL" in str(exc) or "Unsupported" in str(exc):  # names a class or function
            raise LegacyCheckpointError(_legacy_message(path)) from None
        reason = f"UnpicklingError: {' '.join(str(exc).split())[:200]}"
    except Exception as exc:  # whatever a damaged file makes the reader raise
        reason = f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"
    raise RunFolderError(f"{path} is damaged ({reason}); delete it to restart the run")


def check_state(state: Any, path: Path) -> dict[str, Any]:
    """``state`` if it is a checkpoint's structure (keys and types; the iteration at least 0).

    Raises:
        RunFolderError: What is wrong, in one line.
    """
    def refuse(problem: str) -> RunFolderError:
        return RunFolderError(f"{path} is no abco checkpoint ({problem}); delete it to restart "
                              "the run")  # fmt: skip

    if not isinstance(state, dict):
        raise refuse(f"a {type(state).__name__}, not a dict")
    if state.get("format", FORMAT) != FORMAT:
        raise refuse(f"format {str(state.get('format'))[:20]}, not {FORMAT}: from a newer abco?")
    missing = [k for k in ("iteration", "method", "torch_rng", "config") if k not in state]
    if missing:
        raise refuse(f"no {', '.join(missing)}")
    iteration, rng = state["iteration"], state["torch_rng"]
    if type(iteration) is not int or iteration < 0:
        raise refuse(f"iteration {str(iteration)[:20]}")
    if not isinstance(state["method"], dict) or not isinstance(state["config"], dict):
        raise refuse("a method state or config that is not a dict")
    expected = torch.get_rng_state()
    if not (isinstance(rng, torch.Tensor) and rng.dtype == expected.dtype
            and rng.shape == expected.shape):  # fmt: skip
        raise refuse("no generator state of torch")
    cuda = state.get("cuda_rng")
    if cuda is not None and not (isinstance(cuda, list) and all(
            isinstance(x, torch.Tensor) and x.dtype == torch.uint8 for x in cuda)):
        raise refuse("no generator states of CUDA")
    counts = state.get("interactions", {})
    if not isinstance(counts, dict) or not all(
            k in INTERACTION_KINDS and type(v) is int and v >= 0 for k, v in counts.items()):
        raise refuse("interaction counts that are not counts of known kinds")
    return state


def load_method_state(method: Method, state: dict[str, Any], path: Path) -> int:
    """Put the checked ``state`` (:func:`load_checkpoint`) into ``method``; its iteration.

    Raises:
        RunFolderError: The iteration is past the run's, or the method's state does not fit
            the method (another network size, missing keys).
    """
    iteration, total = state["iteration"], method.num_iterations
    if iteration >= total:
        raise RunFolderError(f"{path} is at iteration {iteration} of a run of {total} "
                             "iterations; delete it to restart the run")  # fmt: skip
    try:
        method.load_state_dict(place_like(state["method"], method.state_dict()))
    except (KeyError, TypeError, ValueError, RuntimeError, IndexError, AttributeError) as exc:
        reason = " ".join(str(exc).split())[:300]
        raise RunFolderError(f"{path} does not fit the run's {type(method).__name__} "
                             f"({type(exc).__name__}: {reason}); delete it to restart the "
                             "run") from None  # fmt: skip
    method.interactions.update(state.get("interactions", {}))
    return iteration


def place_like(restored: Any, current: Any) -> Any:
    """``restored`` with each tensor on the device of the tensor at the same place (key, index)
    of ``current``, the method's state before the restore; tensors with no counterpart, and
    everything else, as they are.

    Example:
        >>> fresh = {"indices": torch.zeros(2, dtype=torch.long, device="meta"), "n": 1}
        >>> place_like({"indices": torch.arange(2), "n": 3}, fresh)["indices"].device
        device(type='meta')
    """
    if isinstance(restored, torch.Tensor):
        if isinstance(current, torch.Tensor) and restored.device != current.device:
            return restored.to(current.device)
        return restored
    if isinstance(restored, dict) and isinstance(current, dict):
        return type(restored)((k, place_like(v, current.get(k))) for k, v in restored.items())
    if (isinstance(restored, (list, tuple)) and isinstance(current, (list, tuple))
            and len(restored) == len(current)):  # fmt: skip
        return type(restored)(place_like(v, c) for v, c in zip(restored, current))
    return restored


def restore(method: Method, state: dict[str, Any], cfg: RunConfig, path: Path) -> int:
    """Put ``state`` back into ``method`` and torch's generators; the next iteration.

    Raises:
        RunFolderError: As :func:`load_method_state`.
    """
    iteration = load_method_state(method, state, path)
    torch.set_rng_state(state["torch_rng"].cpu())
    if state.get("cuda_rng") is not None and cfg.device.startswith("cuda"):
        try:
            torch.cuda.set_rng_state_all([x.cpu() for x in state["cuda_rng"]])
        except (RuntimeError, ValueError, IndexError) as exc:
            raise RunFolderError(f"{path} holds CUDA generator states this machine cannot "
                                 f"take ({type(exc).__name__}); resume with --device cpu"
                                 ) from None  # fmt: skip
    return iteration + 1


def convert_legacy_checkpoint(run_dir: str | os.PathLike[str]) -> Path:
    """Rewrite ``RUN_DIR/checkpoint.pt`` of an older abco (a pickle) as data; its path.

    Only for run folders you trust: this is the one place abco unpickles a checkpoint
    (``torch.load(weights_only=False)``), which runs whatever code the file names. A
    checkpoint already of data is left as it is. The new checkpoint is written atomically,
    under the run folder's lock (:func:`~abco_train.harness.run_lock.run_folder_lock`).

    Raises:
        RunFolderError: No checkpoint there, a damaged one, one holding objects that are no
            data (the message names them), or the folder in use.
        OSError: It cannot be read or written.
    """
    path = Path(run_dir) / CHECKPOINT
    if not os.path.lexists(path):
        raise RunFolderError(f"{run_dir} holds no {CHECKPOINT} to convert")
    with run_folder_lock(run_dir, "abco convert-checkpoint (only for run folders you trust)"):
        with open_regular(path) as handle:
            raw = handle.read()
        try:
            check_state(from_saved(_safe_load(raw, path)), path)
            return path  # data already
        except LegacyCheckpointError:
            pass
        try:  # the one unpickling: runs code; the caller trusts this folder
            state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=False)
        except Exception as exc:  # whatever a damaged pickle makes the reader raise
            raise RunFolderError(f"{path} is damaged ({type(exc).__name__}: "
                                 f"{' '.join(str(exc).split())[:200]})") from None  # fmt: skip
        try:
            payload = to_saved(state, "checkpoint")
        except TypeError as exc:
            raise RunFolderError(f"{path} cannot be converted: {exc}") from None
        if isinstance(payload, dict):
            payload = {**payload, "format": FORMAT}
        check_state(from_saved(payload, str(path)), path)
        _write(path, payload)
    return path

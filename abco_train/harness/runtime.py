"""Where and how a run computes: its seeds, torch's threads and kernels, its device.

Every random draw of a run comes from its seed: python's and torch's generators are seeded
here (:func:`seed_everything`, which returns the run's one numpy generator), and a part of a
method that needs a stream of its own (a learner library, a fixed data split) takes a seed
derived from the run's with a tag (:func:`derived_seed`), so it moves none of the other draws.
"""

from __future__ import annotations

import random

import numpy as np
import torch

from abco_train.config.fields import ConfigError
from abco_train.harness.code_version import code_version

__all__ = ["seed_everything", "derived_seed", "derived_rng", "resolve_device", "code_version"]


def seed_everything(seed: int, threads: int = 2, deterministic: bool = True) -> np.random.Generator:
    """Seed python and torch, return the run's numpy Generator (the only numpy randomness);
    make torch's CPU kernels deterministic where cheap."""
    random.seed(seed)
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    torch.set_flush_denormal(True)
    _deterministic_kernels(deterministic)
    return np.random.default_rng(seed)


def _deterministic_kernels(mode: bool) -> None:
    """``torch.use_deterministic_algorithms(mode, warn_only=True)`` without its import of
    ``torch._inductor`` (2.5 s of every run's start on the 2-core machine, 10 s under load),
    which only sets the compiler's flag; abco never compiles. Falls back to the public call
    where torch lacks the setter."""
    setter = getattr(torch._C, "_set_deterministic_algorithms", None)
    if setter is None:
        torch.use_deterministic_algorithms(mode, warn_only=True)
    else:
        setter(mode, warn_only=True)


def derived_seed(*parts: int) -> int:
    """A 31-bit seed of its own from ``parts`` (the run's seed and a tag, say).

    Example:
        >>> derived_seed(0, 0x6A1F0) == derived_seed(0, 0x6A1F0) != derived_seed(1, 0x6A1F0)
        True
    """
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1)[0] >> 1)


def derived_rng(seed: int, tag: int) -> np.random.Generator:
    """A numpy generator of its own for one part of a run (``tag`` names the part): fixed by
    the run's seed, and drawing from it moves none of the run's other draws.

    Example:
        >>> int(derived_rng(3, 0x1D).integers(100)) == int(derived_rng(3, 0x1D).integers(100))
        True
    """
    return np.random.default_rng([seed, tag])


def resolve_device(device: str, arch: str | None = None) -> str:
    """``auto`` -> ``cuda`` when a CUDA device is available, else ``cpu``; with ``arch``
    ``mlp`` (vector observations) ``cpu`` whatever is available: those networks are too small
    for a GPU to pay for its transfers (a GPU machine ran CartPole's cells 0.55-1.10 times as
    fast as one CPU thread).

    Raises:
        ConfigError: ``cuda`` asked for where torch sees no CUDA device.
    """
    if device == "auto":
        return "cuda" if torch.cuda.is_available() and arch != "mlp" else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"--device {device}: torch {torch.__version__} sees no CUDA device "
                          "here; use --device cpu or auto")  # fmt: skip
    return device

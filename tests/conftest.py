"""Shared test set-up: headless SDL for the pygame paths, a non-interactive plot backend, and
caches of the session's own.

The tests never write to the user's caches: before anything is imported (huggingface_hub
reads ``HF_HOME`` when it is imported), ``ABCO_DATA_HOME``, ``HF_HOME``, ``HF_HUB_CACHE`` and
``MINARI_DATASETS_PATH`` point into one temporary folder, removed when the session ends. A
test that needs a cache of its own sets these again (``monkeypatch.setenv``).
"""

import os
import shutil
import tempfile
from pathlib import Path

# Set before anything imports pygame or matplotlib: tests never need a display or a sound card.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
os.environ.setdefault("MPLBACKEND", "Agg")

#: The session's stand-ins for the user's caches (never setdefault: a user's own value is
#: exactly what the tests must not write to).
SESSION_HOME = Path(tempfile.mkdtemp(prefix="abco-tests-"))
os.environ["ABCO_DATA_HOME"] = str(SESSION_HOME / "abco")
os.environ["HF_HOME"] = str(SESSION_HOME / "hf")
os.environ["HF_HUB_CACHE"] = str(SESSION_HOME / "hf" / "hub")
os.environ["MINARI_DATASETS_PATH"] = str(SESSION_HOME / "minari")
os.environ.pop("HUGGINGFACE_HUB_CACHE", None)  # huggingface_hub's older name for the cache


def pytest_unconfigure(config):
    """Remove the session's caches."""
    shutil.rmtree(SESSION_HOME, ignore_errors=True)

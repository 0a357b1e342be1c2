"""Getting a dataset (abco_data.hub.fetch) against a local server speaking the Hub's file endpoints.

Every test runs with a fresh :class:`hub_server.HubServer` on 127.0.0.1, a temporary
huggingface_hub cache, ``ABCO_DATA_HOME`` (abco cache) and ``ABCO_DATA_MANIFEST`` (a manifest
written for the test). ``abco_data.hub.fetch`` uses huggingface_hub's own settings, which
``huggingface_hub.constants`` reads from ``HF_ENDPOINT``/``HF_HOME``/``HF_HUB_OFFLINE`` when it
is imported: in this process the tests patch those constants (:func:`use_endpoint`,
:func:`use_hf_cache`, :func:`go_offline`), and one test runs a subprocess with ``HF_ENDPOINT``
set before anything is imported, as a user would.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import json
import logging
import os
import socket
import stat
import subprocess
import sys
import textwrap
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hub_server import HubServer

import abco_data
from abco_data import cli, progress
from abco_data.errors import (
    ChecksumError,
    DatasetError,
    DatasetNotAvailableError,
    InvalidParameterError,
    InvalidTargetError,
    UnknownDatasetError,
)
from abco_data.hub import fetch as hub
from abco_data.hub import publish
from abco_data.progress import LogProgress

REPO = "abco-datasets/abco"
DATASET = "abco/maze3x3-expert-v0"
FILENAME = "maze3x3-expert-v0.hdf5"
OTHER = "abco/cartpole-pre-v0"


@dataclass
class HubEnv:
    """What a test gets: the server, the published bytes, and the folders in use."""

    server: HubServer
    data: bytes
    commit: str
    manifest: Path
    abco_cache: Path
    hf_cache: Path

    def write_manifest(self, files: dict[str, dict[str, Any]] | None = None, **top: Any) -> None:
        """Rewrite the test manifest (default: DATASET -> the published bytes)."""
        if files is None:
            files = {DATASET: entry_for(FILENAME, self.data)}
        payload = {"revision": self.commit, "repo_id": REPO, "files": files, **top}
        self.manifest.write_text(json.dumps(payload))

    def file_requests(self) -> list[str]:
        """'METHOD path' of the requests for files (resolve endpoint) the server received."""
        return [f"{r.method} {r.path}" for r in self.server.requests if "/resolve/" in r.path]

    def abco_files(self) -> list[str]:
        """Every name in the abco cache folder, hidden temporary files included."""
        return sorted(os.listdir(self.abco_cache)) if self.abco_cache.exists() else []

    def hf_leftovers(self) -> list[Path]:
        """Partial downloads left in the huggingface_hub cache."""
        return sorted(self.hf_cache.rglob("*.incomplete"))


def entry_for(filename: str, data: bytes) -> dict[str, Any]:
    return {"filename": filename, "size": len(data), "sha256": hashlib.sha256(data).hexdigest()}


class _NoSleepTime:
    """Stands in for the ``time`` module inside huggingface_hub: retries without waiting."""

    def __init__(self) -> None:
        import time

        self._time = time
        self.sleeps: list[float] = []

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._time, name)


@pytest.fixture
def no_sleep(monkeypatch: pytest.MonkeyPatch) -> _NoSleepTime:
    """huggingface_hub's retry back-off (1 s, 2 s, ...) without the waiting."""
    import huggingface_hub.file_download as file_download
    import huggingface_hub.utils._http as http

    fake = _NoSleepTime()
    monkeypatch.setattr(file_download, "time", fake)
    monkeypatch.setattr(http, "time", fake)
    return fake


def use_endpoint(monkeypatch: pytest.MonkeyPatch, url: str) -> None:
    """Point huggingface_hub at ``url``, as ``HF_ENDPOINT=url`` before its import would."""
    import huggingface_hub.constants as constants

    monkeypatch.setenv("HF_ENDPOINT", url)  # for subprocesses
    monkeypatch.setattr(constants, "ENDPOINT", url)
    monkeypatch.setattr(constants, "HUGGINGFACE_CO_URL_TEMPLATE",
                        url + "/{repo_id}/resolve/{revision}/{filename}")


def use_hf_cache(monkeypatch: pytest.MonkeyPatch, hf_home: Path) -> None:
    """Use ``hf_home/hub`` as huggingface_hub's cache, as ``HF_HOME=hf_home`` would."""
    import huggingface_hub.constants as constants

    monkeypatch.setenv("HF_HOME", str(hf_home))  # for subprocesses
    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(hf_home / "hub"))


def go_offline(monkeypatch: pytest.MonkeyPatch) -> None:
    """huggingface_hub's offline mode, as ``HF_HUB_OFFLINE=1`` before its import would."""
    import huggingface_hub.constants as constants

    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)


@pytest.fixture
def hub_env(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_sleep: _NoSleepTime
) -> Any:
    """A running local Hub with DATASET published, and the environment pointing at it."""
    import huggingface_hub.constants as constants

    data = os.urandom(300_000)
    with HubServer() as server:
        commit = server.publish(REPO, {FILENAME: data, "README.md": b"# abco\n"})
        env = HubEnv(
            server=server,
            data=data,
            commit=commit,
            manifest=tmp_path / "manifest.json",
            abco_cache=tmp_path / "abco",
            hf_cache=tmp_path / "hf" / "hub",
        )
        env.write_manifest()
        for name in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_HUB_CACHE",
                     "HUGGINGFACE_HUB_CACHE", "HF_TOKEN"):
            monkeypatch.delenv(name, raising=False)
        use_endpoint(monkeypatch, server.url)
        use_hf_cache(monkeypatch, tmp_path / "hf")
        monkeypatch.setenv("ABCO_DATA_HOME", str(env.abco_cache))
        monkeypatch.setenv("ABCO_DATA_MANIFEST", str(env.manifest))
        # huggingface_hub read HF_HUB_OFFLINE when it was imported: make sure it is off here.
        monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
        # Small read chunks so that a download interrupted mid-body has data to resume from.
        monkeypatch.setattr(constants, "DOWNLOAD_CHUNK_SIZE", 64 * 1024)
        # huggingface_hub asks {ENDPOINT}/api/agent-harnesses once a day for its user agent;
        # give it an empty registry so no test talks to the real Hub.
        import huggingface_hub.utils._detect_agent as detect_agent

        monkeypatch.setattr(detect_agent, "_registry", {})
        yield env


def fake_generator(data: bytes, calls: list[tuple[str, Path]] | None = None) -> Any:
    """A stand-in for abco_data.generate that writes ``data`` (atomically, like the real one)."""

    def generate(dataset_id: str, path: Any = None, *, progress: bool = True, **kw: Any) -> Path:
        target = Path(path)
        if calls is not None:
            calls.append((dataset_id, target))
        tmp = target.with_name(target.name + ".part")
        tmp.write_bytes(data)
        os.replace(tmp, target)
        return target

    return generate


# --------------------------------------------------------------------------- downloading


def test_download_verifies_and_caches(hub_env: HubEnv) -> None:
    path = hub.download(DATASET, progress=False)
    assert path == hub_env.abco_cache / FILENAME
    assert path.read_bytes() == hub_env.data
    assert hub_env.abco_files() == [FILENAME]
    # The pinned commit is what was asked for, with a HEAD for metadata then a GET.
    resolve = f"/datasets/{REPO}/resolve/{hub_env.commit}/{FILENAME}"
    assert hub_env.file_requests() == [f"HEAD {resolve}", f"GET {resolve}"]
    # The huggingface_hub cache keeps its copy too (used offline later).
    assert list(hub_env.hf_cache.glob(f"datasets--abco-datasets--abco/snapshots/*/{FILENAME}"))


def test_load_opens_the_fetched_file(hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch) -> None:
    opened: list[Path] = []
    monkeypatch.setattr(hub, "open_dataset", lambda p: opened.append(Path(p)) or "dataset")
    assert hub.load(DATASET, progress=False) == "dataset"
    assert opened == [hub_env.abco_cache / FILENAME]
    assert opened[0].read_bytes() == hub_env.data


def test_second_fetch_is_served_from_cache_without_network(hub_env: HubEnv) -> None:
    first = hub.fetch(DATASET, progress=False)
    hub_env.server.reset_requests()
    second = hub.fetch(DATASET, progress=False)
    assert second == first
    assert hub_env.server.requests == []


def test_progress_false_passes_huggingface_hubs_silent_bar(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    from huggingface_hub.utils import silent_tqdm

    seen: list[Any] = []
    real = hub.hf_hub_download

    def spy(*args: Any, **kwargs: Any) -> Any:
        seen.append(kwargs.get("tqdm_class"))
        return real(*args, **kwargs)

    monkeypatch.setattr(hub, "hf_hub_download", spy)
    hub.download(DATASET, progress=False)
    assert seen == [silent_tqdm]  # huggingface_hub's own do-nothing bar
    hub.download(DATASET, cache_dir=hub_env.abco_cache / "other", progress=True)
    # Not a terminal here (pytest captures stderr): whole lines for a log; on a terminal,
    # None: huggingface_hub's own bars, as it configures them.
    assert seen[-1] is LogProgress
    monkeypatch.setattr(progress, "is_terminal", lambda stream: True)
    hub.download(DATASET, cache_dir=hub_env.abco_cache / "third", progress=True)
    assert seen[-1] is None


def test_interrupted_download_resumes_and_ends_verified(hub_env: HubEnv) -> None:
    hub_env.server.interrupt(FILENAME, after=150_000, times=1)
    path = hub.download(DATASET, progress=False)
    assert path.read_bytes() == hub_env.data
    gets = [r for r in hub_env.server.requests if r.method == "GET" and "/resolve/" in r.path]
    assert len(gets) == 2
    assert "range" not in gets[0].headers
    assert gets[1].headers["range"].startswith("bytes=")  # resumed, not restarted
    assert int(gets[1].headers["range"][6:].rstrip("-")) > 0
    assert hub_env.abco_files() == [FILENAME]
    assert hub_env.hf_leftovers() == []


def test_download_that_keeps_failing_leaves_nothing_then_succeeds(hub_env: HubEnv) -> None:
    hub_env.server.interrupt(FILENAME, after=0, times=None)  # every GET dies before any byte
    with pytest.raises(DatasetNotAvailableError, match=FILENAME) as info:
        hub.download(DATASET, progress=False)
    assert hub_env.server.url in str(info.value)
    assert hub_env.abco_files() == []
    assert hub_env.hf_leftovers() == []
    assert not list(hub_env.hf_cache.rglob("blobs/*"))
    hub_env.server.clear_faults()
    path = hub.download(DATASET, progress=False)
    assert path.read_bytes() == hub_env.data
    assert hub_env.abco_files() == [FILENAME]


def test_corrupted_file_on_the_hub_is_never_cached(hub_env: HubEnv) -> None:
    bad = bytearray(hub_env.data)
    bad[1234] ^= 0xFF
    hub_env.server.set_file(REPO, hub_env.commit, FILENAME, bytes(bad))
    with pytest.raises(ChecksumError) as info:
        hub.download(DATASET, progress=False)
    message = str(info.value)
    assert hashlib.sha256(hub_env.data).hexdigest() in message
    assert hashlib.sha256(bytes(bad)).hexdigest() in message
    assert str(hub_env.hf_cache) in message  # names the downloaded file
    assert hub_env.abco_files() == []
    # The bad copy is not kept in the huggingface_hub cache either, so a retry downloads again.
    assert not [p for p in hub_env.hf_cache.rglob(FILENAME) if p.exists()]
    assert not list(hub_env.hf_cache.rglob("blobs/*"))


def test_corrupted_file_on_the_hub_falls_back_to_generation(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    hub_env.server.set_file(REPO, hub_env.commit, FILENAME, b"x" * len(hub_env.data))
    calls: list[tuple[str, Path]] = []
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data, calls))
    with caplog.at_level(logging.WARNING, logger="abco_data.hub.fetch"):
        path = hub.fetch(DATASET, progress=False)
    assert [c[0] for c in calls] == [DATASET]
    assert path.read_bytes() == hub_env.data
    assert "does not match the manifest" in caplog.text
    assert "generating" in caplog.text
    assert hub_env.abco_files() == [FILENAME]


@pytest.mark.parametrize("in_place", [False, True], ids=["rewritten", "in-place"])
def test_corrupted_cached_file_is_reported_and_replaced(
    hub_env: HubEnv, caplog: pytest.LogCaptureFixture, in_place: bool
) -> None:
    path = hub.fetch(DATASET, progress=False)
    bad = bytearray(path.read_bytes())
    bad[-1] ^= 0x01
    if in_place:
        # Damage the file itself: the abco copy may be a hard link to huggingface_hub's blob,
        # which is then bad too and must be downloaded again.
        with open(path, "r+b") as handle:
            handle.write(bytes(bad))
    else:
        path.unlink()
        path.write_bytes(bytes(bad))
    with caplog.at_level(logging.WARNING, logger="abco_data.hub.fetch"):
        again = hub.fetch(DATASET, progress=False)
    assert again == path
    assert again.read_bytes() == hub_env.data
    assert str(path) in caplog.text
    assert hashlib.sha256(bytes(bad)).hexdigest() in caplog.text
    assert hashlib.sha256(hub_env.data).hexdigest() in caplog.text
    assert hub_env.abco_files() == [FILENAME]


def test_bad_copy_in_hf_cache_is_fetched_again(hub_env: HubEnv) -> None:
    hub.download(DATASET, progress=False)
    (hub_env.abco_cache / FILENAME).unlink()
    blob = next(hub_env.hf_cache.rglob("blobs/*"))
    blob.write_bytes(b"\0" * len(hub_env.data))  # also corrupts nothing else: no abco copy
    hub_env.server.reset_requests()
    path = hub.download(DATASET, progress=False)
    assert path.read_bytes() == hub_env.data
    assert any(r.startswith("GET ") for r in hub_env.file_requests())


def test_file_missing_on_the_hub_falls_back_to_generation(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    hub_env.write_manifest(files={OTHER: entry_for("cartpole-pre-v0.hdf5", b"other bytes")})
    with pytest.raises(DatasetNotAvailableError, match="cartpole-pre-v0.hdf5"):
        hub.download(OTHER, progress=False)
    monkeypatch.setattr(hub, "generate", fake_generator(b"other bytes"))
    path = hub.fetch(OTHER, progress=False)
    assert path.read_bytes() == b"other bytes"


def test_unreachable_hub_falls_back_to_generation(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, no_sleep: _NoSleepTime
) -> None:
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{probe.getsockname()[1]}"
    use_endpoint(monkeypatch, dead)
    with pytest.raises(DatasetNotAvailableError, match="127.0.0.1"):
        hub.download(DATASET, progress=False)
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data))
    assert hub.fetch(DATASET, progress=False).read_bytes() == hub_env.data
    assert hub_env.server.requests == []


# --------------------------------------------------------------------------- offline


def test_offline_serves_the_abco_cache(hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch) -> None:
    path = hub.fetch(DATASET, progress=False)
    hub_env.server.reset_requests()
    go_offline(monkeypatch)
    assert hub.fetch(DATASET, progress=False) == path
    assert hub_env.server.requests == []


def test_offline_serves_the_huggingface_hub_cache(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    hub.download(DATASET, progress=False)
    (hub_env.abco_cache / FILENAME).unlink()
    hub_env.server.reset_requests()
    go_offline(monkeypatch)
    monkeypatch.setattr(hub, "generate", fake_generator(b"must not be used"))
    path = hub.fetch(DATASET, progress=False)
    assert path.read_bytes() == hub_env.data
    assert hub_env.server.requests == []


def test_offline_with_nothing_generates(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[tuple[str, Path]] = []
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data, calls))
    path = hub.fetch(DATASET, offline=True, progress=False)
    assert path.read_bytes() == hub_env.data
    # Generated under a hidden temporary name in the cache folder, then renamed.
    assert calls[0][1].parent == hub_env.abco_cache
    assert calls[0][1].name.startswith(".")
    assert hub_env.abco_files() == [FILENAME]
    assert hub_env.server.requests == []


def test_generated_file_that_differs_raises_checksum_error(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(hub, "generate", fake_generator(b"not it"))
    with pytest.raises(ChecksumError, match="locally generated file"):
        hub.fetch(DATASET, offline=True, progress=False)
    assert hub_env.abco_files() == []


def test_dataset_missing_from_manifest_is_generated_and_logged(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    hub_env.write_manifest(files={})
    monkeypatch.setattr(hub, "generate", fake_generator(b"fresh"))
    with caplog.at_level(logging.INFO, logger="abco_data.hub.fetch"):
        path = hub.fetch(DATASET, progress=False)
    assert path.read_bytes() == b"fresh"
    assert "no entry for abco/maze3x3-expert-v0" in caplog.text
    assert hub_env.server.requests == []
    with pytest.raises(DatasetNotAvailableError, match="no entry"):
        hub.download(DATASET, progress=False)


def test_cached_copy_without_manifest_entry_is_never_used_unchecked(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    hub_env.write_manifest(files={})
    hub_env.abco_cache.mkdir()
    (hub_env.abco_cache / FILENAME).write_bytes(b"tampered")
    monkeypatch.setattr(hub, "generate", fake_generator(b"fresh"))
    assert hub.fetch(DATASET, progress=False).read_bytes() == b"fresh"


# --------------------------------------------------------------------------- cache safety


def test_evicting_a_bad_copy_never_follows_a_link_out_of_the_cache(
    hub_env: HubEnv, tmp_path: Path
) -> None:
    hub.download(DATASET, progress=False)
    (hub_env.abco_cache / FILENAME).unlink()
    snapshot = next(hub_env.hf_cache.rglob(f"snapshots/*/{FILENAME}"))
    outside = tmp_path / "precious.bin"
    outside.write_bytes(b"not the dataset, and not the cache's to delete")
    snapshot.unlink()
    snapshot.symlink_to(outside)
    path = hub.download(DATASET, progress=False)  # bad copy evicted, downloaded again
    assert path.read_bytes() == hub_env.data
    assert outside.read_bytes() == b"not the dataset, and not the cache's to delete"


def test_stale_temporaries_of_killed_runs_are_removed(hub_env: HubEnv) -> None:
    hub_env.abco_cache.mkdir()
    dead = hub_env.abco_cache / f".{FILENAME}.999999999-0123abcd.generating.abco-tmp"
    mine = hub_env.abco_cache / f".{FILENAME}.{os.getpid()}-0123abcd.incoming.abco-tmp"
    old_style = hub_env.abco_cache / f".{FILENAME}.{'0' * 32}.tmp"
    other = hub_env.abco_cache / "notes.txt"
    for path in (dead, mine, old_style, other):
        path.write_bytes(b"x")
    os.utime(old_style, (1, 1))  # 1970: long stale
    hub.fetch(DATASET, progress=False)
    assert hub_env.abco_files() == sorted([FILENAME, mine.name, other.name])


def test_full_abco_cache_uses_the_verified_hub_copy(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def no_space(*args: Any, **kwargs: Any) -> Path:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(hub, "install_verified", no_space)
    with caplog.at_level(logging.WARNING, logger="abco_data.hub.fetch"):
        path = hub.fetch(DATASET, progress=False)
    assert path.is_relative_to(hub_env.hf_cache) and path.read_bytes() == hub_env.data
    assert "No space left on device" in caplog.text and str(hub_env.abco_cache) in caplog.text


# --------------------------------------------------------------------------- ids, manifest


def test_unknown_id_lists_the_known_ones(hub_env: HubEnv) -> None:
    with pytest.raises(UnknownDatasetError) as info:
        hub.load("abco/maze4x4-expert-v0", progress=False)
    assert "abco/maze4x4-expert-v0" in str(info.value)
    for known in abco_data.DATASET_IDS:
        assert known in str(info.value)
    with pytest.raises(UnknownDatasetError):
        hub.cached_path("nope")


def test_cached_path_follows_abco_data_home(hub_env: HubEnv) -> None:
    assert hub.cached_path(DATASET) == hub_env.abco_cache / FILENAME
    assert hub.cached_path(DATASET, "/x") == Path("/x") / FILENAME


def test_invalid_manifest_is_a_clear_error(hub_env: HubEnv) -> None:
    hub_env.manifest.write_text(json.dumps({"revision": "a", "files": {DATASET: {"size": 1}}}))
    with pytest.raises(abco_data.DatasetError, match=str(hub_env.manifest)):
        hub.fetch(DATASET, progress=False)


def test_shipped_manifest_is_valid() -> None:
    manifest = hub.read_manifest(Path(abco_data.__file__).with_name("manifest.json"))
    assert manifest.repo_id == REPO
    for dataset_id in manifest.files:
        assert dataset_id in abco_data.DATASET_IDS


def test_subprocess_with_hf_endpoint_set_before_import(hub_env: HubEnv) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST")}
    code = textwrap.dedent(
        f"""
        import huggingface_hub.constants as c
        assert c.ENDPOINT == {hub_env.server.url!r}, c.ENDPOINT
        from abco_data.hub import fetch as hub
        path = hub.download({DATASET!r}, progress=False)
        print(path)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=Path(__file__).resolve().parents[2],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip().splitlines()[-1]).read_bytes() == hub_env.data


# --------------------------------------------------------------------------- push


def _tiny_hdf5(path: Path, dataset_id: str, env_id: str) -> Path:
    h5py = pytest.importorskip("h5py")
    import numpy as np

    with h5py.File(path, "w") as handle:
        handle.attrs.update(
            {
                "format": "abco-dataset",
                "format_version": 1,
                "dataset_id": dataset_id,
                "kind": "expert",
                "env_id": env_id,
                "num_episodes": 1,
                "creation_params": json.dumps({"seed": 0}),
            }
        )
        handle.create_dataset("observations", data=np.zeros((2, 4), dtype=np.float32))
    return path


def test_push_commits_file_and_card_to_the_local_hub(hub_env: HubEnv, tmp_path: Path) -> None:
    hub_env.write_manifest(files={})
    repo = "maintainer/abco-test"
    first = _tiny_hdf5(tmp_path / "a.hdf5", DATASET, "AbcoMaze3x3-v0")
    commit = publish.push(DATASET, repo, path=first, token="hf_test")
    assert len(commit) == 40
    files = hub_env.server.files(repo, commit)
    assert files[FILENAME] == first.read_bytes()
    card = files["README.md"].decode()
    assert card.startswith("---\nlicense: mit\n")
    assert "task_categories:\n- reinforcement-learning" in card
    assert "- AbcoMaze3x3-v0" in card
    assert f"## `{DATASET}`" in card
    assert hashlib.sha256(first.read_bytes()).hexdigest() in card
    assert f"File `{FILENAME}`" in card
    posts = [r.path for r in hub_env.server.requests if r.method == "POST"]
    assert f"/api/datasets/{repo}/commit/main" in posts
    assert all(r.headers.get("authorization") == "Bearer hf_test" for r in hub_env.server.requests
               if r.method == "POST")

    second = _tiny_hdf5(tmp_path / "b.hdf5", OTHER, "CartPole-v1")
    commit2 = publish.push(OTHER, repo, path=second, token="hf_test")
    card2 = hub_env.server.files(repo, commit2)["README.md"].decode()
    assert f"## `{DATASET}`" in card2 and f"## `{OTHER}`" in card2  # sections accumulate
    assert "- AbcoMaze3x3-v0" in card2 and "- CartPole-v1" in card2

    # What was pushed downloads and verifies against a manifest pinned to the new commit.
    hub_env.commit = commit2
    hub_env.write_manifest(files={DATASET: entry_for(FILENAME, first.read_bytes())}, repo_id=repo)
    assert hub.download(DATASET, progress=False).read_bytes() == first.read_bytes()


def test_push_refuses_a_file_that_differs_from_the_manifest(
    hub_env: HubEnv, tmp_path: Path
) -> None:
    wrong = tmp_path / "wrong.hdf5"
    wrong.write_bytes(b"wrong")
    with pytest.raises(ChecksumError, match="file to push"):
        publish.push(DATASET, "maintainer/abco-test", path=wrong, token="hf_test")
    assert [r for r in hub_env.server.requests if r.method == "POST"] == []


# --------------------------------------------------------------------------- real generator


def test_load_end_to_end_with_the_real_generator(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Publish a tiny real dataset, load it from the Hub, then regenerate it offline."""
    pytest.importorskip("abco_envs.experts.classic")
    overrides = {"layouts": 2, "episodes_per_layout": 2, "reference_episodes": 2}
    dataset_id, filename = "abco/maze3x3-pre-v0", "maze3x3-pre-v0.hdf5"
    published = abco_data.generate(dataset_id, tmp_path / filename, progress=False, **overrides)
    data = published.read_bytes()
    hub_env.commit = hub_env.server.publish(REPO, {filename: data})
    hub_env.write_manifest(files={dataset_id: entry_for(filename, data)})

    dataset = hub.load(dataset_id, progress=False)
    assert dataset.id == dataset_id
    assert Path(dataset.path) == hub_env.abco_cache / filename

    # Offline with empty caches: the generator (same overrides) rebuilds the same bytes.
    (hub_env.abco_cache / filename).unlink()
    use_hf_cache(monkeypatch, tmp_path / "empty-hf")
    monkeypatch.setattr(hub, "generate", functools.partial(abco_data.generate, **overrides))
    hub_env.server.reset_requests()
    regenerated = hub.load(dataset_id, offline=True, progress=False)
    assert Path(regenerated.path).read_bytes() == data
    assert hub_env.server.requests == []


# --------------------------------------------------------------------------- bounded Hub calls


def _abco_hub_workers() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "abco-hub-call"]


def _hub_warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name.startswith("huggingface_hub")
            and r.levelno >= logging.WARNING]


@pytest.mark.parametrize("method", ["HEAD", "GET"])
def test_hub_that_never_answers_falls_back_to_generation(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture,
    method: str,
) -> None:
    monkeypatch.setenv("ABCO_HUB_TIMEOUT", "0.5")
    hub_env.server.stall(FILENAME, method=method)
    with pytest.raises(DatasetNotAvailableError, match="no complete answer within 0.5 s") as err:
        hub.download(DATASET, progress=False)
    assert "ABCO_HUB_TIMEOUT" in str(err.value) and FILENAME in str(err.value)
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data))
    with caplog.at_level(logging.WARNING):
        assert hub.fetch(DATASET, progress=False).read_bytes() == hub_env.data
    assert _hub_warnings(caplog) == []  # huggingface_hub's retries stay quiet
    assert [r.getMessage() for r in caplog.records if r.name == "abco_data.hub.fetch"] == [
        f"{err.value}; generating {DATASET} locally instead"]


def test_hub_that_drips_falls_back_and_stops_downloading(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ABCO_HUB_TIMEOUT", "0.5")
    hub_env.server.stall(FILENAME, method="GET", drip=0.01)  # 300 kB: hours at this pace
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data))
    assert hub.fetch(DATASET, progress=False).read_bytes() == hub_env.data
    gets = [r for r in hub_env.file_requests() if r.startswith("GET")]
    assert gets  # the download had started, and was dripping
    # The abandoned worker stops at its next chunk: nothing keeps downloading in the
    # background (the join's bound is generous; the worker stops a chunk after the limit).
    for worker in _abco_hub_workers():
        worker.join(timeout=30)
        assert not worker.is_alive()


def test_hub_announcing_a_huge_file_falls_back_before_any_download(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    hub_env.server.announce_size(FILENAME, 10**12)
    with pytest.raises(DatasetNotAvailableError, match="announces 1000000000000 bytes"):
        hub.download(DATASET, progress=False)
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data))
    assert hub.fetch(DATASET, progress=False).read_bytes() == hub_env.data
    assert not [r for r in hub_env.file_requests() if r.startswith("GET")]


def test_huggingface_hubs_too_large_error_is_a_hub_failure(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch
) -> None:
    def too_large(*args: Any, **kwargs: Any) -> Any:
        raise ValueError("The file is too large to be downloaded using the regular download"
                         " method.")

    monkeypatch.setattr(hub, "hf_hub_download", too_large)
    with pytest.raises(DatasetNotAvailableError, match="ValueError: The file is too large"):
        hub.download(DATASET, progress=False)
    monkeypatch.setattr(hub, "generate", fake_generator(hub_env.data))
    assert hub.fetch(DATASET, progress=False).read_bytes() == hub_env.data


@pytest.mark.parametrize("value", ["abc", "0", "-1", "nan", "1e9"])
def test_bad_hub_timeout_is_one_clear_error(
    hub_env: HubEnv, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    value: str,
) -> None:
    monkeypatch.setenv("ABCO_HUB_TIMEOUT", value)
    with pytest.raises(InvalidParameterError, match=f"ABCO_HUB_TIMEOUT must be .* got '{value}'"):
        hub.fetch(DATASET, progress=False)
    assert cli.main(["download", DATASET, "--quiet"]) == cli.EXIT_BAD_INPUT
    assert capsys.readouterr().err.startswith("error: ABCO_HUB_TIMEOUT must be")
    assert hub_env.server.requests == []


def test_hub_retry_noise_folds_into_one_error_line(
    hub_env: HubEnv, capfd: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    hub_env.server.interrupt(FILENAME, after=0, times=None)  # every GET dies: retries
    with caplog.at_level(logging.WARNING):
        assert cli.main(["download", DATASET, "--quiet"]) == cli.EXIT_FAILED
    gets = [r for r in hub_env.file_requests() if r.startswith("GET")]
    assert len(gets) > 2  # huggingface_hub did retry ...
    assert _hub_warnings(caplog) == []  # ... without a word
    err = capfd.readouterr().err
    assert err.startswith("error: could not get") and err.count("\n") == 1, err
    assert logging.getLogger("huggingface_hub").level != logging.ERROR  # restored after


@pytest.mark.parametrize("repo", ["../../x", "a/b/c", "name-only", "owner/x..y", ""])
def test_push_refuses_a_bad_repo_id_before_any_request(
    hub_env: HubEnv, tmp_path: Path, capsys: pytest.CaptureFixture[str], repo: str
) -> None:
    path = _tiny_hdf5(tmp_path / "a.hdf5", DATASET, "AbcoMaze3x3-v0")
    with pytest.raises(InvalidParameterError, match="invalid Hub repo id"):
        publish.push(DATASET, repo, path=path, token="hf_test")
    assert cli.main(["push", DATASET, "--repo", repo, "--path", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: invalid Hub repo id {repo!r}") and err.count("\n") == 1
    assert hub_env.server.requests == []


def test_manifest_with_a_bad_repo_id_is_a_clear_error(hub_env: HubEnv) -> None:
    hub_env.write_manifest(repo_id="../../x")
    with pytest.raises(DatasetError, match="invalid dataset manifest .*'repo_id'"):
        hub.fetch(DATASET, progress=False)


def test_fifo_in_the_cache_is_never_read_or_replaced(hub_env: HubEnv) -> None:
    hub_env.abco_cache.mkdir(parents=True)
    fifo = hub_env.abco_cache / FILENAME
    os.mkfifo(fifo)
    with pytest.raises(InvalidTargetError, match="FIFO"):  # not a hang on the FIFO
        hub.fetch(DATASET, progress=False)
    with pytest.raises(InvalidTargetError, match="FIFO"):
        hub.download(DATASET, progress=False)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert hub_env.file_requests() == [] and hub_env.abco_files() == [FILENAME]

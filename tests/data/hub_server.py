"""A local stand-in for the Hugging Face Hub's file endpoints, for tests.

:class:`HubServer` runs a threading HTTP server on ``127.0.0.1`` (port 0: the OS picks one) and
speaks what ``huggingface_hub`` needs to download and to commit files:

- ``HEAD``/``GET /{datasets/}{repo}/resolve/{revision}/{path}``: the file, with the headers the
  client reads (``X-Repo-Commit``, ``ETag``, ``X-Linked-Etag``, ``X-Linked-Size``,
  ``Content-Length``, ``Accept-Ranges``), ``Range: bytes=N-`` answered with 206 and
  ``Content-Range``, and the Hub's ``X-Error-Code`` on 404 (``RepoNotFound``,
  ``RevisionNotFound``, ``EntryNotFound``). No Xet headers, so the client uses plain HTTP.
- ``POST /api/repos/create``, ``POST /api/validate-yaml``,
  ``POST /api/{type}s/{repo}/preupload/{revision}`` (every file "regular") and
  ``POST /api/{type}s/{repo}/commit/{revision}`` (NDJSON with base64 ``file`` lines).

Every request is recorded in :attr:`HubServer.requests`; faults can be armed with
:meth:`HubServer.interrupt` (send part of a body, then drop the connection),
:meth:`HubServer.stall` (accept and never answer, or drip the answer a byte at a time) and
:meth:`HubServer.announce_size` (claim another size for a file).

Example:
    >>> with HubServer() as hub:
    ...     commit = hub.publish("owner/data", {"a.bin": b"abc"})
    ...     len(commit), hub.url.startswith("http://127.0.0.1:")
    (40, True)
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import json
import socket
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import unquote, urlsplit

__all__ = ["HubServer", "Recorded"]

_PREFIX = {"dataset": "datasets/", "model": "", "space": "spaces/"}


@dataclass(frozen=True)
class Recorded:
    """One request the server received.

    Attributes:
        method: HTTP method.
        path: Request path (unquoted, without the query).
        headers: Request headers, names lower-cased.
    """

    method: str
    path: str
    headers: dict[str, str]


@dataclass
class _Repo:
    commits: dict[str, dict[str, bytes]] = field(default_factory=dict)
    refs: dict[str, str] = field(default_factory=dict)
    messages: dict[str, str] = field(default_factory=dict)


@dataclass
class _Fault:
    path: str
    after: int
    times: int | None


@dataclass
class _Stall:
    path: str
    method: str
    drip: float | None  # None: never answer


class HubServer:
    """A Hub stand-in on 127.0.0.1; use as a context manager or call start/stop."""

    def __init__(self) -> None:
        self.requests: list[Recorded] = []
        self._repos: dict[tuple[str, str], _Repo] = {}
        self._faults: list[_Fault] = []
        self._stalls: list[_Stall] = []
        self._sizes: dict[str, int] = {}
        self._release = threading.Event()  # set: stalled answers give up
        self._lock = threading.Lock()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    # ----------------------------------------------------------------- lifecycle

    @property
    def url(self) -> str:
        """Base URL, e.g. ``http://127.0.0.1:54321`` (what HF_ENDPOINT should be set to)."""
        if self._server is None:
            raise RuntimeError("the server is not running")
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}"

    def start(self) -> HubServer:
        """Start serving in a daemon thread."""
        handler = type("Handler", (_Handler,), {"hub": self})
        self._server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the socket (stalled answers give up)."""
        self._release.set()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None

    def __enter__(self) -> HubServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ----------------------------------------------------------------- content

    def publish(
        self,
        repo_id: str,
        files: dict[str, bytes],
        *,
        repo_type: str = "dataset",
        branch: str = "main",
        message: str = "publish",
    ) -> str:
        """Create (or extend) a repo with a commit adding ``files``; return the commit id."""
        with self._lock:
            repo = self._repos.setdefault((repo_type, repo_id), _Repo())
            return self._commit(repo, branch, files, [], message)

    def set_file(
        self, repo_id: str, commit: str, path: str, data: bytes, *, repo_type: str = "dataset"
    ) -> None:
        """Change a file's bytes in place at an existing commit (to simulate corruption)."""
        with self._lock:
            self._repos[(repo_type, repo_id)].commits[commit][path] = data

    def files(
        self, repo_id: str, revision: str = "main", *, repo_type: str = "dataset"
    ) -> dict[str, bytes]:
        """The files of a repo at a revision (a copy)."""
        with self._lock:
            repo = self._repos[(repo_type, repo_id)]
            return dict(repo.commits[repo.refs.get(revision, revision)])

    def interrupt(self, path: str, *, after: int, times: int | None = 1) -> None:
        """Make the next ``times`` GETs of a file (None: all) stop after ``after`` body bytes."""
        with self._lock:
            self._faults.append(_Fault(path=path, after=after, times=times))

    def stall(self, path: str, *, method: str = "GET", drip: float | None = None) -> None:
        """Make every ``method`` request of a file stall: never answer (``drip=None``), or
        send the headers and then one byte of the body every ``drip`` seconds; until
        :meth:`clear_faults` or :meth:`stop`."""
        with self._lock:
            self._release.clear()
            self._stalls.append(_Stall(path=path, method=method, drip=drip))

    def announce_size(self, path: str, size: int) -> None:
        """Claim ``size`` bytes for a file in its ``X-Linked-Size`` header (the body stays)."""
        with self._lock:
            self._sizes[path] = size

    def clear_faults(self) -> None:
        """Disarm every fault."""
        with self._lock:
            self._faults.clear()
            self._stalls.clear()
            self._sizes.clear()
        self._release.set()

    def reset_requests(self) -> None:
        """Forget the recorded requests."""
        with self._lock:
            self.requests.clear()

    # ----------------------------------------------------------------- internals

    @staticmethod
    def _commit(
        repo: _Repo, branch: str, added: dict[str, bytes], deleted: list[str], message: str
    ) -> str:
        parent = repo.refs.get(branch)
        tree = dict(repo.commits.get(parent, {})) if parent else {}
        tree.update(added)
        for path in deleted:
            tree.pop(path, None)
        digest = hashlib.sha1()
        digest.update((parent or "").encode())
        digest.update(message.encode())
        for path in sorted(tree):
            digest.update(path.encode() + b"\0" + hashlib.sha256(tree[path]).digest())
        commit = digest.hexdigest()
        repo.commits[commit] = tree
        repo.refs[branch] = commit
        repo.messages[commit] = message
        return commit

    def _stall_of(self, path: str, method: str) -> _Stall | None:
        with self._lock:
            return next((x for x in self._stalls if x.path == path and x.method == method), None)

    def _take_fault(self, path: str) -> _Fault | None:
        with self._lock:
            for fault in self._faults:
                if fault.path == path and (fault.times is None or fault.times > 0):
                    if fault.times is not None:
                        fault.times -= 1
                    return fault
        return None


class _Handler(BaseHTTPRequestHandler):
    hub: HubServer
    protocol_version = "HTTP/1.0"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - stdlib signature
        """Stay quiet."""

    # ----------------------------------------------------------------- helpers

    def _record(self) -> str:
        path = unquote(urlsplit(self.path).path)
        with self.hub._lock:
            self.hub.requests.append(
                Recorded(self.command, path, {k.lower(): v for k, v in self.headers.items()})
            )
        return path

    def _send(self, status: int, body: bytes = b"", headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        for key, value in (headers or {}).items():
            self.send_header(key, value)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if self.command != "HEAD" and body:
            self.wfile.write(body)

    def _json(self, status: int, payload: Any, headers: dict[str, str] | None = None) -> None:
        self._send(
            status,
            json.dumps(payload).encode(),
            {"Content-Type": "application/json", **(headers or {})},
        )

    def _error(self, status: int, code: str, message: str, commit: str | None = None) -> None:
        headers = {"X-Error-Code": code, "X-Error-Message": message}
        if commit:
            headers["X-Repo-Commit"] = commit
        self._json(status, {"error": message}, headers)

    def _body(self) -> bytes:
        length = int(self.headers.get("Content-Length") or 0)
        return self.rfile.read(length) if length else b""

    @staticmethod
    def _split_repo(rest: str) -> tuple[str, str, str]:
        """``datasets/o/n/...`` -> (type, "o/n", remainder)."""
        repo_type = "model"
        for kind, prefix in _PREFIX.items():
            if prefix and rest.startswith(prefix):
                repo_type, rest = kind, rest[len(prefix) :]
                break
        owner, name, remainder = (rest.split("/", 2) + ["", ""])[:3]
        return repo_type, f"{owner}/{name}", remainder

    # ----------------------------------------------------------------- file endpoints

    def do_HEAD(self) -> None:  # noqa: N802 - stdlib name
        self._resolve(self._record())

    def do_GET(self) -> None:  # noqa: N802 - stdlib name
        self._resolve(self._record())

    def _resolve(self, path: str) -> None:
        repo_type, repo_id, remainder = self._split_repo(path.lstrip("/"))
        if not remainder.startswith("resolve/"):
            self._error(404, "NotFound", f"no route for {path}")
            return
        # The revision is URL-quoted by the client: split the raw path to keep "a/b" refs intact.
        raw = urlsplit(self.path).path.lstrip("/")
        raw_remainder = raw.split("/resolve/", 1)[1]
        revision = unquote(raw_remainder.split("/", 1)[0])
        filename = unquote(raw_remainder.split("/", 1)[1]) if "/" in raw_remainder else ""
        with self.hub._lock:
            repo = self.hub._repos.get((repo_type, repo_id))
            if repo is None:
                self._error(404, "RepoNotFound", "Repository not found")
                return
            commit = repo.refs.get(revision, revision if revision in repo.commits else None)
            if commit is None:
                self._error(404, "RevisionNotFound", f"Invalid rev id: {revision}")
                return
            data = repo.commits[commit].get(filename)
        if data is None:
            self._error(404, "EntryNotFound", f"{filename} does not exist", commit)
            return
        etag = hashlib.sha256(data).hexdigest()
        with self.hub._lock:
            announced = self.hub._sizes.get(filename, len(data))
        headers = {
            "X-Repo-Commit": commit,
            "ETag": f'"{etag}"',
            "X-Linked-Etag": f'"{etag}"',
            "X-Linked-Size": str(announced),
            "Accept-Ranges": "bytes",
            "Content-Type": "application/octet-stream",
        }
        start, status = 0, 200
        range_header = self.headers.get("Range")
        if range_header and range_header.startswith("bytes="):
            first, _, last = range_header[6:].partition("-")
            start = int(first or 0)
            end = int(last) if last else len(data) - 1
            if start >= len(data):
                self._send(416, b"", {"Content-Range": f"bytes */{len(data)}"})
                return
            headers["Content-Range"] = f"bytes {start}-{end}/{len(data)}"
            data, status = data[start : end + 1], 206
        stall = self.hub._stall_of(filename, self.command)
        if stall is not None:
            self._stalled(stall, status, data, headers)
            return
        fault = self.hub._take_fault(filename) if self.command == "GET" else None
        if fault is None:
            self._send(status, data, headers)
            return
        # Promise the whole body, send part of it, then drop the connection.
        self.send_response(status)
        for key, value in headers.items():
            self.send_header(key, value)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data[: fault.after])
        self.wfile.flush()
        self.close_connection = True
        with contextlib.suppress(OSError):
            self.connection.shutdown(socket.SHUT_RDWR)

    def _stalled(self, stall: _Stall, status: int, data: bytes, headers: dict[str, str]) -> None:
        """Never answer, or drip the answer; give up when the server releases stalls."""
        release = self.hub._release
        if stall.drip is None:
            release.wait()
        else:
            self.send_response(status)
            for key, value in headers.items():
                self.send_header(key, value)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            with contextlib.suppress(OSError):
                for i in range(len(data)):
                    if release.is_set():
                        break
                    self.wfile.write(data[i : i + 1])
                    self.wfile.flush()
                    time.sleep(stall.drip)
        self.close_connection = True
        with contextlib.suppress(OSError):
            self.connection.shutdown(socket.SHUT_RDWR)

    # ----------------------------------------------------------------- API endpoints

    def do_POST(self) -> None:  # noqa: N802 - stdlib name
        path = self._record()
        body = self._body()
        if path == "/api/repos/create":
            self._create_repo(json.loads(body or b"{}"))
        elif path == "/api/validate-yaml":
            self._json(200, {"errors": [], "warnings": []})
        elif path.startswith("/api/"):
            repo_type_plural, _, rest = path[len("/api/") :].partition("/")
            repo_type = repo_type_plural.rstrip("s")
            owner, name, tail = (rest.split("/", 2) + ["", ""])[:3]
            action, _, revision = tail.partition("/")
            repo_id = f"{owner}/{name}"
            with self.hub._lock:
                repo = self.hub._repos.get((repo_type, repo_id))
            if repo is None:
                self._error(404, "RepoNotFound", "Repository not found")
            elif action == "preupload":
                files = json.loads(body)["files"]
                self._json(
                    200,
                    {
                        "files": [
                            {"path": f["path"], "uploadMode": "regular", "shouldIgnore": False}
                            for f in files
                        ]
                    },
                )
            elif action == "commit":
                self._commit(repo, repo_type, repo_id, revision or "main", body)
            else:
                self._error(404, "NotFound", f"no route for {path}")
        else:
            self._error(404, "NotFound", f"no route for {path}")

    def _create_repo(self, payload: dict[str, Any]) -> None:
        repo_type = payload.get("type") or "model"
        repo_id = f"{payload.get('organization') or 'user'}/{payload['name']}"
        url = f"{self.hub.url}/{_PREFIX.get(repo_type, '')}{repo_id}"
        with self.hub._lock:
            key = (repo_type, repo_id)
            if key in self.hub._repos:
                self._json(409, {"error": "You already created this repo", "url": url})
                return
            repo = _Repo()
            self.hub._repos[key] = repo
            HubServer._commit(repo, "main", {".gitattributes": b"*.h5 filter=lfs\n"}, [], "init")
        self._json(200, {"url": url, "name": repo_id})

    def _commit(self, repo: _Repo, repo_type: str, repo_id: str, branch: str, body: bytes) -> None:
        added: dict[str, bytes] = {}
        deleted: list[str] = []
        message = "commit"
        for line in body.splitlines():
            if not line.strip():
                continue
            item = json.loads(line)
            key, value = item["key"], item["value"]
            if key == "header":
                message = value.get("summary") or message
            elif key == "file":
                if value.get("encoding") != "base64":
                    self._error(400, "BadRequest", "only base64 files are supported")
                    return
                added[value["path"]] = base64.b64decode(value["content"])
            elif key in ("deletedFile", "deletedFolder"):
                deleted.append(value["path"])
            else:
                self._error(400, "BadRequest", f"unsupported commit line {key!r}")
                return
        with self.hub._lock:
            commit = HubServer._commit(repo, branch, added, deleted, message)
        prefix = _PREFIX.get(repo_type, "")
        self._json(
            200,
            {
                "commitUrl": f"{self.hub.url}/{prefix}{repo_id}/commit/{commit}",
                "commitOid": commit,
                "pullRequestUrl": None,
            },
        )

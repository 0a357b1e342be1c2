"""Misbehaving Hub endpoints on 127.0.0.1, for the Hub cases of family 5.

:class:`BadHub` serves one of these behaviours (``mode``) to every connection:

- ``silent``: accepts, reads the request, and never answers;
- ``drip-headers``: starts a response and sends its headers one byte every half second;
- ``drip-body``: answers ``HEAD`` as the Hub would for the file, then sends the body one
  byte every half second;
- ``huge``: says the file is 10^12 bytes (``HEAD`` and ``GET``), and sends at most 32 MiB;
- ``503``: answers every request at once with ``503 Service Unavailable``.

A well-behaved Hub is ``tests/data/hub_server.py``'s ``HubServer``.
"""

from __future__ import annotations

import socket
import socketserver
import threading
import time
from typing import Any

MODES = ("silent", "drip-headers", "drip-body", "huge", "503")
HUGE = 10**12


class BadHub:
    """A Hub endpoint that misbehaves as ``mode`` says; a context manager.

    Args:
        mode: One of :data:`MODES`.
        revision: The commit it claims to serve (``X-Repo-Commit``).
        size: The file's true size (``drip-body``'s ``Content-Length``).
        sha256: The file's sha256 (its ``ETag``).
    """

    def __init__(self, mode: str, revision: str = "0" * 40, size: int = 1000,
                 sha256: str = "0" * 64) -> None:  # fmt: skip
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r}")
        self.mode, self.revision, self.size, self.sha256 = mode, revision, size, sha256
        self.stop = threading.Event()
        self.requests = 0
        outer = self

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                outer.serve(self.request)

        self._server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Handler,
                                                       bind_and_activate=True)  # fmt: skip
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        kwargs={"poll_interval": 0.05}, daemon=True)  # fmt: skip

    @property
    def url(self) -> str:
        """What ``HF_ENDPOINT`` should be."""
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}"

    def __enter__(self) -> BadHub:
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop.set()
        self._server.shutdown()
        self._server.server_close()

    def _headers(self, length: int) -> bytes:
        etag = f'"{self.sha256}"'
        lines = ["HTTP/1.1 200 OK", f"X-Repo-Commit: {self.revision}", f"ETag: {etag}",
                 f"X-Linked-Etag: {etag}", f"X-Linked-Size: {length}",
                 f"Content-Length: {length}", "Accept-Ranges: bytes",
                 "Content-Type: application/octet-stream", "Connection: close"]  # fmt: skip
        return ("\r\n".join(lines) + "\r\n\r\n").encode()

    def _drip(self, conn: socket.socket, data: bytes) -> None:
        for i in range(len(data)):
            if self.stop.wait(0.5):
                return
            conn.sendall(data[i : i + 1])

    def serve(self, conn: socket.socket) -> None:
        """Answer one connection as :attr:`mode` says."""
        conn.settimeout(5)
        try:
            request = conn.recv(65536)
        except OSError:
            return
        self.requests += 1
        method = request.split(b" ", 1)[0]
        try:
            if self.mode == "silent":
                self.stop.wait()
            elif self.mode == "drip-headers":
                self._drip(conn, b"HTTP/1.1 200 OK\r\n" + b"X-Slow: " + b"a" * 100000)
            elif self.mode == "drip-body":
                conn.sendall(self._headers(self.size))
                if method == b"GET":
                    self._drip(conn, b"\0" * self.size)
            elif self.mode == "huge":
                conn.sendall(self._headers(HUGE))
                if method == b"GET":
                    chunk = b"\0" * 2**20
                    for _ in range(32):
                        if self.stop.is_set():
                            break
                        conn.sendall(chunk)
            else:
                body = b'{"error": "Service Unavailable"}'
                conn.sendall(b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: "
                             b"application/json\r\nContent-Length: " + str(len(body)).encode()
                             + b"\r\nConnection: close\r\n\r\n" + body)  # fmt: skip
        except OSError:
            pass
        finally:
            time.sleep(0.01)
            conn.close()


def closed_port() -> int:
    """A port on 127.0.0.1 nothing listens on (connections are refused)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]

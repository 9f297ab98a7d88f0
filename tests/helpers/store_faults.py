"""Faults of the job store for the tests: a SQLite database locked by another process, a damaged
SQLite file, a PostgreSQL server stopped and started (``pg_ctlcluster``, or a TCP proxy in front
of it when the test may not control the server), and a store that raises (a full disk)."""

from __future__ import annotations

import contextlib
import random
import shlex
import socket
import sqlite3
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy.engine import Connection

from api.store import JobStore

# what a response body or a job error must never show: SQL, the driver's words, a URL, a password
LEAKS = ("select ", "insert ", "update jobs", "where ", "sqlite3", "psycopg", "operationalerror", "databaseerror",
         "postgresql+", "postgresql://", "secret", "[sql", "parameters")


def assert_no_leak(text: str) -> None:
    low = text.lower()
    for word in LEAKS:
        assert word not in low, f"{word!r} in {text!r}"


def assert_store_503(r: Any, reason: str | None = None) -> None:
    """A response of a store that is away: JSON 503, Retry-After, store unavailable, nothing leaked."""
    assert r.status_code == 503, (r.status_code, r.text)
    assert r.headers["content-type"].startswith("application/json"), r.headers
    assert int(r.headers["retry-after"]) >= 1
    body = r.json()
    assert body["store"] == "unavailable" and body["errors"][0]["type"] == "store_unavailable", body
    if reason is not None:
        assert f"({reason})" in body["detail"], body
    assert_no_leak(r.text)


_HOLDER = """
import sqlite3, sys
c = sqlite3.connect(sys.argv[1], isolation_level=None, timeout=30)
c.execute("BEGIN EXCLUSIVE")
print("locked", flush=True)
sys.stdin.readline()
c.execute("ROLLBACK")
"""


@contextmanager
def sqlite_locked(path: Path) -> Iterator[None]:
    """Another process holds an exclusive lock on the database until the block ends (WAL: every
    writer waits, readers read the last committed state)."""
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
        yield
    finally:
        if proc.stdin is not None:
            proc.stdin.write("\n")
            proc.stdin.close()
        proc.wait(10)


def damage_sqlite(path: Path, keep: int, seed: int = 0) -> None:
    """Garbage over every byte from ``keep`` on: 100 keeps only the valid header, 4096 the first page."""
    data = bytearray(path.read_bytes())
    rng = random.Random(seed)
    for i in range(keep, len(data)):
        data[i] = rng.randrange(256)
    for extra in (path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        extra.unlink(missing_ok=True)
    path.write_bytes(bytes(data))


class FaultyStore(JobStore):
    """A real store that raises while ``fault`` is set: ``"full"`` (writes fail as on a full disk)
    or ``"unreachable"`` (everything fails, with SQL and a password in the driver's error). The
    error goes through the store's own translation (``_guard``)."""

    fault: str | None = None

    @contextmanager
    def _tx(self, write: bool = True) -> Iterator[Connection]:
        if self.fault == "full" and write:
            with self._guard():
                raise sqlite3.OperationalError("database or disk is full")
        if self.fault == "unreachable":
            from sqlalchemy.exc import OperationalError

            with self._guard():
                raise OperationalError("SELECT jobs.id FROM jobs WHERE jobs.owner = %(owner)s",
                                       {"owner": "secret"}, Exception("connection to postgresql://u:secret@h refused"))
        with super()._tx(write) as c:
            yield c


class PostgresOutage:
    """Stops and starts the test's PostgreSQL: with ``ctl`` (``pg_ctlcluster 15 main``) the real
    server; without it, a TCP proxy on 127.0.0.1 that the service connects through (``url``),
    whose stop drops every connection and refuses new ones, as a stopped server does."""

    def __init__(self, url: str, ctl: str | None):
        from sqlalchemy.engine import make_url

        self.ctl = shlex.split(ctl) if ctl else None
        self._target = make_url(url)
        self.url = url
        self._listener: socket.socket | None = None
        self._conns: list[socket.socket] = []
        self._lock = threading.Lock()
        if self.ctl is None:
            self._port = _free_port()
            self.url = self._target.set(host="127.0.0.1", port=self._port).render_as_string(hide_password=False)
            self.start()

    def stop(self) -> None:
        if self.ctl is not None:
            subprocess.run([*self.ctl, "stop"], check=True, capture_output=True)
            return
        with self._lock:
            if self._listener is not None:
                with _quiet():  # wakes the accept() that close() alone would leave listening (Linux)
                    self._listener.shutdown(socket.SHUT_RDWR)
                self._listener.close()
                self._listener = None
            for c in self._conns:
                with _quiet():
                    c.shutdown(socket.SHUT_RDWR)
                c.close()
            self._conns.clear()

    def start(self) -> None:
        if self.ctl is not None:
            subprocess.run([*self.ctl, "start"], check=True, capture_output=True)
            return
        ls = socket.socket()
        ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        ls.bind(("127.0.0.1", self._port))
        ls.listen(64)
        self._listener = ls
        threading.Thread(target=self._accept, args=(ls,), daemon=True).start()

    def _accept(self, ls: socket.socket) -> None:
        while True:
            try:
                client, _ = ls.accept()
            except OSError:
                return
            try:
                upstream = socket.create_connection((self._target.host or "127.0.0.1", self._target.port or 5432))
            except OSError:
                client.close()
                continue
            with self._lock:
                self._conns += [client, upstream]
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=_pipe, args=(a, b), daemon=True).start()


def _pipe(src: socket.socket, dst: socket.socket) -> None:
    with _quiet():
        while data := src.recv(65536):
            dst.sendall(data)
    with _quiet():
        dst.shutdown(socket.SHUT_WR)


def _quiet() -> contextlib.suppress:
    return contextlib.suppress(OSError)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])

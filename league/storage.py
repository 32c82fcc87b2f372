"""Content-addressed file storage: ``<root>/<kind>/<ab>/<sha256><suffix>``.

A file is written to a temporary name (``.tmp-*``) in the same folder, fsynced and renamed
into place, so a reader never sees a partial file and a crash leaves at most a stray temp
file (:mod:`league.sweep` removes those, and files no row refers to, at server start).
Reads check the bytes against their address, so a file replaced on disk is never used.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

SHA256 = re.compile(r"^[0-9a-f]{64}$")
KINDS = {"models": ".zip", "traces": ".json"}
TEMP_PREFIX = ".tmp-"
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
PROBE_BYTES = 4096


class StorageError(OSError):
    """The file store could not take a write (disk full, read-only, no permission)."""

    def __init__(self, action: str, cause: OSError) -> None:
        reason = cause.strerror or str(cause)
        super().__init__(cause.errno, f"{action}: {type(cause).__name__}: {reason}")
        self.full = cause.errno in FULL_ERRNOS

    def __str__(self) -> str:
        return str(self.strerror)


class DigestMismatch(ValueError):
    """A stored file's bytes no longer hash to its address: it was replaced or corrupted."""


class Storage:
    """Files addressed by the sha256 of their content, grouped by kind."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self._probed: tuple[float, str | None] | None = None

    def path(self, kind: str, sha256: str) -> Path:
        """Where the file of ``kind`` with this digest lives (it may not exist)."""
        if kind not in KINDS or not SHA256.match(sha256):
            raise ValueError(f"bad storage address {kind}/{sha256}")
        return self.root / kind / sha256[:2] / f"{sha256}{KINDS[kind]}"

    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
        """Store ``data``; return its sha256 and whether this call created the file.

        A file already there gets a fresh mtime, so the start-up sweep's grace period also
        covers a row about to refer to it. Raises :class:`StorageError` when the write fails.
        """
        sha256 = hashlib.sha256(data).hexdigest()
        target = self.path(kind, sha256)
        try:
            os.utime(target)
            return sha256, False
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise StorageError(f"could not store a {kind} file", exc) from exc
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            _write_durably(target, data)
        except OSError as exc:
            raise StorageError(f"could not store a {kind} file", exc) from exc
        return sha256, True

    def read(self, kind: str, sha256: str) -> bytes:
        """The stored bytes (``FileNotFoundError`` when absent, :class:`DigestMismatch` when
        they no longer hash to ``sha256``)."""
        data = self.path(kind, sha256).read_bytes()
        if hashlib.sha256(data).hexdigest() != sha256:
            raise DigestMismatch(f"stored {kind} file {sha256} does not match its sha256")
        return data

    def remove(self, kind: str, sha256: str) -> None:
        """Delete a stored file if present."""
        self.path(kind, sha256).unlink(missing_ok=True)

    def files(self, kind: str) -> list[Path]:
        """Every stored file of ``kind`` (temp files included, so tests can spot leftovers)."""
        folder = self.root / kind
        return sorted(p for p in folder.rglob("*") if p.is_file()) if folder.exists() else []

    def temp_files(self, older_than: float) -> Iterator[Path]:
        """Temp files (``.tmp-*``, anywhere in the store) last modified before ``older_than``."""
        if self.root.exists():
            for path in self.root.rglob(f"{TEMP_PREFIX}*"):
                if _mtime(path) < older_than:
                    yield path

    def stored(self, kind: str, older_than: float) -> Iterator[tuple[str, Path]]:
        """``(sha256, path)`` of each stored file of ``kind`` last modified before
        ``older_than`` (temp files and stray names are not stored files)."""
        folder = self.root / kind
        if not folder.exists():
            return
        for path in folder.glob(f"??/*{KINDS[kind]}"):
            sha256 = path.name.removesuffix(KINDS[kind])
            addressed = SHA256.match(sha256) and path.parent.name == sha256[:2]
            if addressed and _mtime(path) < older_than:
                yield sha256, path

    def write_problem(self, max_age: float = 1.0) -> str | None:
        """Why the store cannot take a small fsynced write right now, or None if it can.

        The answer is reused for ``max_age`` seconds, so a readiness probe polled often
        costs at most one write a second.
        """
        now = time.monotonic()
        if self._probed is None or now - self._probed[0] >= max_age:
            self._probed = (now, self._try_write())
        return self._probed[1]

    def _try_write(self) -> str | None:
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}probe-", dir=self.root)
            try:
                with os.fdopen(fd, "wb") as handle:
                    handle.write(b"\0" * PROBE_BYTES)
                    handle.flush()
                    os.fsync(handle.fileno())
            finally:
                Path(tmp).unlink(missing_ok=True)
        except OSError as exc:
            return str(StorageError("the file store cannot take a write", exc))
        return None


def _write_durably(target: Path, data: bytes) -> None:
    """Write ``data`` to a temp file beside ``target``, fsync, rename into place."""
    fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_dir(target.parent)


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except FileNotFoundError:  # removed meanwhile (another process swept or renamed it)
        return float("inf")


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # some platforms cannot open folders; the rename is still atomic
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)

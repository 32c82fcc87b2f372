"""Content-addressed file storage: ``<kind>/<ab>/<sha256><suffix>`` under a root.

:class:`FileStore` is what callers use: ``put``, ``read`` (checked against the sha256),
``remove``, the readiness probe and the start-up sweep's hooks. :func:`open_storage` picks
the store from the settings: :class:`Storage`, a local directory (the embedded default), or
:class:`league.storage_s3.S3Storage`, a bucket of an S3-compatible object store.

In the local store a file is written to a temporary name (``.tmp-*``) in the same folder,
fsynced and renamed into place, so a reader never sees a partial file and a crash leaves at
most a stray temp file (:mod:`league.sweep` removes those, and files no row refers to, at
server start). Reads check the bytes against their address, so a replaced file is never used.
"""

from __future__ import annotations

import errno
import hashlib
import logging
import os
import re
import tempfile
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from league.settings import Settings

log = logging.getLogger("slipstream.storage")
SHA256 = re.compile(r"^[0-9a-f]{64}$")
KINDS = {"models": ".zip", "traces": ".json"}
TEMP_PREFIX = ".tmp-"
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
PROBE_BYTES = 4096


class StorageError(OSError):
    """The file store could not take a write or answer a read (disk full, read-only, no
    permission; for object storage also an unreachable endpoint, a missing bucket or
    rejected credentials). ``full`` tells a full store (507) from other failures (503)."""

    def __init__(
        self, action: str, cause: BaseException, reason: str | None = None, full: bool = False
    ) -> None:
        code = cause.errno if isinstance(cause, OSError) else None
        if reason is None:
            reason = (cause.strerror if isinstance(cause, OSError) else None) or str(cause)
        super().__init__(code, f"{action}: {type(cause).__name__}: {reason}")
        self.full = full or code in FULL_ERRNOS

    def __str__(self) -> str:
        return str(self.strerror)


class DigestMismatch(ValueError):
    """A stored file's bytes no longer hash to its address: it was replaced or corrupted."""


def address(kind: str, sha256: str) -> str:
    """The relative name of a stored file, ``<kind>/<ab>/<sha256><suffix>``."""
    if kind not in KINDS or not SHA256.match(sha256):
        raise ValueError(f"bad storage address {kind}/{sha256}")
    return f"{kind}/{sha256[:2]}/{sha256}{KINDS[kind]}"


def checked(kind: str, sha256: str, data: bytes) -> bytes:
    """``data`` if it hashes to ``sha256``, else :class:`DigestMismatch`."""
    if hashlib.sha256(data).hexdigest() != sha256:
        raise DigestMismatch(f"stored {kind} file {sha256} does not match its sha256")
    return data


class FileStore(ABC):
    """Files addressed by the sha256 of their content, grouped by kind."""

    _probed: tuple[float, str | None] | None = None

    @abstractmethod
    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
        """Store ``data``; return its sha256 and whether this call created the file.

        A file already there is marked fresh, so the start-up sweep's grace period also
        covers a row about to refer to it. Raises :class:`StorageError` when the write fails.
        """

    @abstractmethod
    def read(self, kind: str, sha256: str) -> bytes:
        """The stored bytes (``FileNotFoundError`` when absent, :class:`DigestMismatch` when
        they no longer hash to ``sha256``)."""

    @abstractmethod
    def remove(self, kind: str, sha256: str) -> None:
        """Delete a stored file if present."""

    @abstractmethod
    def remove_temp(self, older_than: float) -> int:
        """Remove crash leftovers last modified before ``older_than``; return how many."""

    @abstractmethod
    def stored(self, kind: str, older_than: float) -> Iterator[str]:
        """The sha256 of each stored file of ``kind`` last modified before ``older_than``."""

    @abstractmethod
    def remove_orphan(
        self, kind: str, sha256: str, older_than: float, wanted: Callable[[], bool]
    ) -> bool:
        """Delete a file no row referred to, unless ``wanted()`` (asked once it is out of
        reach) says a row now does or it was stored again since ``older_than``; return
        whether it went."""

    @abstractmethod
    def _try_write(self) -> str | None:
        """Why a small write fails right now, or None."""

    def write_problem(self, max_age: float = 1.0) -> str | None:
        """Why the store cannot take a small write right now, or None if it can.

        The answer is reused for ``max_age`` seconds, so a readiness probe polled often
        costs at most one write a second.
        """
        now = time.monotonic()
        if self._probed is None or now - self._probed[0] >= max_age:
            self._probed = (now, self._try_write())
        return self._probed[1]


def open_storage(settings: Settings) -> FileStore:
    """The file store ``settings`` name: ``storage_url`` (``s3://bucket/prefix``) or the
    data directory's ``files`` folder."""
    if settings.storage_url:
        from league.storage_s3 import S3Storage  # boto3 only when object storage is used

        return S3Storage(settings.storage_url, endpoint_url=settings.s3_endpoint_url)
    return Storage(settings.storage_dir)


class Storage(FileStore):
    """The local store: files under a directory (a shared mount for several hosts)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def path(self, kind: str, sha256: str) -> Path:
        """Where the file of ``kind`` with this digest lives (it may not exist)."""
        return self.root / address(kind, sha256)

    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
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
        return checked(kind, sha256, self.path(kind, sha256).read_bytes())

    def remove(self, kind: str, sha256: str) -> None:
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

    def remove_temp(self, older_than: float) -> int:
        return sum(_unlink(path) for path in list(self.temp_files(older_than)))

    def stored(self, kind: str, older_than: float) -> Iterator[str]:
        """Temp files and stray names are not stored files."""
        folder = self.root / kind
        if not folder.exists():
            return
        for path in folder.glob(f"??/*{KINDS[kind]}"):
            sha256 = path.name.removesuffix(KINDS[kind])
            addressed = SHA256.match(sha256) and path.parent.name == sha256[:2]
            if addressed and _mtime(path) < older_than:
                yield sha256

    def remove_orphan(
        self, kind: str, sha256: str, older_than: float, wanted: Callable[[], bool]
    ) -> bool:
        """The file is renamed aside first, so a ``put`` meanwhile writes it anew, and one
        just before refreshed the mtime the renamed file keeps."""
        path = self.path(kind, sha256)
        aside = path.with_name(f"{TEMP_PREFIX}orphan-{path.name}")
        try:
            os.rename(path, aside)
        except FileNotFoundError:  # another server's sweep got there first
            return False
        if wanted() or _mtime(aside) >= older_than:
            if path.exists():  # an upload wrote the same bytes anew meanwhile
                aside.unlink()
            else:
                os.replace(aside, path)
            return False
        return bool(_unlink(aside))

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


def _unlink(path: Path) -> int:
    try:
        path.unlink()
    except FileNotFoundError:
        return 0
    except OSError as exc:
        log.warning("could not remove %s: %s", path, exc)
        return 0
    return 1


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # some platforms cannot open folders; the rename is still atomic
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)

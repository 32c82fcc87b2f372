"""What every file store is: files addressed by the sha256 of their content.

A stored file's name is ``<kind>/<ab>/<sha256><suffix>`` under the store's root (a folder
for :class:`league.store.local.LocalFileStore`, a bucket prefix for
:class:`league.store.s3.S3FileStore`). :class:`FileStore` is what callers use: ``put``,
``read`` (checked against the sha256), ``remove``, the readiness probe and the start-up
sweep's hooks (:mod:`league.store.sweep`). Reads check the bytes against their address, so
a replaced file is never used.
"""

from __future__ import annotations

import errno
import hashlib
import re
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator

SHA256 = re.compile(r"^[0-9a-f]{64}$")
KINDS = {"models": ".zip", "traces": ".json", "runs": ".zip"}
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

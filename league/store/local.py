"""The local file store: content-addressed files under a directory (the embedded default).

A file is written to a temporary name (``.tmp-*``) in the same folder, fsynced and renamed
into place, so a reader never sees a partial file and a crash leaves at most a stray temp
file (:mod:`league.store.sweep` removes those, and files no row refers to, at server
start). The directory may be a shared mount for several hosts.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from league.store.base import (
    KINDS,
    PROBE_BYTES,
    SHA256,
    TEMP_PREFIX,
    FileStore,
    StorageError,
    address,
    checked,
)

log = logging.getLogger("slipstream.storage")


class LocalFileStore(FileStore):
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

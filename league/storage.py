"""Content-addressed file storage: ``<root>/<kind>/<ab>/<sha256><suffix>``.

A file is written to a temporary name in the same folder, fsynced and renamed into place,
so a reader never sees a partial file and a crash leaves at most a stray temp file.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path

SHA256 = re.compile(r"^[0-9a-f]{64}$")
KINDS = {"models": ".zip", "traces": ".json"}


class Storage:
    """Files addressed by the sha256 of their content, grouped by kind."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def path(self, kind: str, sha256: str) -> Path:
        """Where the file of ``kind`` with this digest lives (it may not exist)."""
        if kind not in KINDS or not SHA256.match(sha256):
            raise ValueError(f"bad storage address {kind}/{sha256}")
        return self.root / kind / sha256[:2] / f"{sha256}{KINDS[kind]}"

    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
        """Store ``data``; return its sha256 and whether this call created the file."""
        sha256 = hashlib.sha256(data).hexdigest()
        target = self.path(kind, sha256)
        if target.exists():
            return sha256, False
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=target.parent)
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
        return sha256, True

    def read(self, kind: str, sha256: str) -> bytes:
        """The stored bytes (``FileNotFoundError`` when absent)."""
        return self.path(kind, sha256).read_bytes()

    def remove(self, kind: str, sha256: str) -> None:
        """Delete a stored file if present."""
        self.path(kind, sha256).unlink(missing_ok=True)

    def files(self, kind: str) -> list[Path]:
        """Every stored file of ``kind`` (temp files included, so tests can spot leftovers)."""
        folder = self.root / kind
        return sorted(p for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # some platforms cannot open folders; the rename is still atomic
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)

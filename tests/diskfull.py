"""A real full disk for tests: a small tmpfs mounted over a folder, then filled to the byte.

Mounting needs root (or CAP_SYS_ADMIN), which developers' machines and CI have here;
without it the test skips, or fails under ``CI=true`` (``tests.prerequisites``).
"""

from __future__ import annotations

import errno
import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.prerequisites import skip_or_fail


@contextmanager
def small_tmpfs(folder: Path, size: str = "2m") -> Iterator[Path]:
    """Mount a tmpfs of ``size`` over ``folder`` (created if missing); unmount afterwards."""
    folder.mkdir(parents=True, exist_ok=True)
    mount = ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)]
    try:
        done = subprocess.run(mount, capture_output=True, text=True, check=False)
    except FileNotFoundError:
        skip_or_fail("a full disk needs a small tmpfs, and this machine has no `mount`")
    if done.returncode != 0:
        skip_or_fail(f"a full disk needs a small tmpfs; mounting one failed: {done.stderr.strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "--lazy", str(folder)], check=True)


def fill(folder: Path) -> Path:
    """Fill the file system holding ``folder`` to the last byte; delete the answer to free it."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    try:
        for chunk in (1 << 16, 1 << 12, 1):
            while True:
                try:
                    os.write(fd, b"\0" * chunk)
                except OSError as exc:
                    assert exc.errno == errno.ENOSPC, exc
                    break
    finally:
        os.close(fd)
    return filler

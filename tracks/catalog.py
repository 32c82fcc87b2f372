"""Finding tracks by name: the built-ins first, then the user's imported tracks.

User tracks live as Slipstream JSON documents in ``$SLIPSTREAM_HOME/tracks``
(``SLIPSTREAM_HOME`` defaults to ``~/.slipstream``), one ``<name>.json`` each. A user
track is read and checked once per version of its file (path, mtime, size), in a bounded
cache, so a server answering for it does not re-check its geometry on every request.

Errors name the track and the problem, never the server's paths, and an unknown name
lists the built-in tracks only (the user's own are listed by ``slipstream tracks list``).
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from dataclasses import dataclass
from functools import cache, lru_cache
from pathlib import Path
from typing import Literal

from tracks.builtin import BUILTIN_DESIGNS, build
from tracks.io import TrackFileError, read_document, read_track, write_document
from tracks.track import Track, TrackError

Direction = Literal["ccw", "cw"]
Source = Literal["builtin", "user"]

NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
USER_TRACK_CACHE_SIZE = 32
"""User track file versions whose reading (track or error) is kept in memory."""


class TrackNotFoundError(TrackError):
    """No built-in or user track has the requested name."""


@dataclass(frozen=True)
class TrackInfo:
    """One row of the catalogue listing."""

    name: str
    display_name: str
    length: float
    width: float
    is_loop: bool
    direction: Direction
    source: Source

    @classmethod
    def of(cls, track: Track, source: Source) -> TrackInfo:
        """Summarise a track."""
        return cls(
            name=track.name,
            display_name=track.display_name,
            length=track.length,
            width=track.width,
            is_loop=track.is_loop,
            direction=track.direction,
            source=source,
        )


def slipstream_home() -> Path:
    """The data directory: ``$SLIPSTREAM_HOME`` or ``~/.slipstream``."""
    return Path(os.environ.get("SLIPSTREAM_HOME") or Path.home() / ".slipstream")


def user_track_dir() -> Path:
    """Where imported tracks are stored (not created until the first import)."""
    return slipstream_home() / "tracks"


def builtin_names() -> list[str]:
    """Names of the built-in tracks, in catalogue order."""
    return list(BUILTIN_DESIGNS)


@cache
def _builtin(name: str) -> Track:
    return build(BUILTIN_DESIGNS[name])


def _user_files() -> dict[str, Path]:
    folder = user_track_dir()
    if not folder.is_dir():
        return {}
    return {
        p.stem: p
        for p in sorted(folder.glob("*.json"))
        if NAME_PATTERN.match(p.stem) and p.stem not in BUILTIN_DESIGNS
    }


@lru_cache(maxsize=USER_TRACK_CACHE_SIZE)
def _read_version(path: Path, inode: int, mtime_ns: int, size: int) -> Track | TrackFileError:
    """One version of a user track file, read and checked (its error kept as well)."""
    try:
        return read_document(path)
    except TrackFileError as exc:
        return TrackFileError(exc.path, exc.problem)  # without the traceback's frames


def _file_version(path: Path) -> tuple[int, int, int]:
    """What changes when a user track file is replaced or written: inode, mtime, size."""
    try:
        stat = path.stat()
    except OSError:
        raise TrackFileError(path, "no such file") from None
    return stat.st_ino, stat.st_mtime_ns, stat.st_size


def _read_user_track(path: Path) -> Track:
    """The user track in ``path``, from the cache while the file is unchanged."""
    result = _read_version(path, *_file_version(path))
    if isinstance(result, TrackFileError):
        raise result
    return result


def _unknown(name: str) -> TrackNotFoundError:
    return TrackNotFoundError(
        f"unknown track {name!r}; the built-in tracks are {', '.join(builtin_names())}; "
        "`slipstream tracks list` lists every track, imported ones included"
    )


def get_track(name: str, direction: Direction | None = None) -> Track:
    """The track called ``name`` (built-in or user), optionally in the given direction.

    Raises :class:`TrackNotFoundError` for an unknown name and :class:`TrackError` for a
    user track whose file is unusable; neither message holds a path or other user tracks.
    """
    if name in BUILTIN_DESIGNS:
        track = _builtin(name)
    else:
        path = _user_files().get(name)
        if path is None:
            raise _unknown(name)
        try:
            track = _read_user_track(path)
        except TrackFileError as exc:
            problem = exc.problem.replace(str(path.parent), "").replace(path.name, name)
            raise TrackError(f"the user track {name!r} cannot be used: {problem}") from None
    return track if direction is None else track.with_direction(direction)


def track_version(name: str) -> tuple[str | int, ...]:
    """A value that changes whenever :func:`get_track` would return another track for
    ``name``: one ``stat`` of a user track's file, without reading it. Raises
    :class:`TrackNotFoundError` as :func:`get_track` does."""
    if name in BUILTIN_DESIGNS:
        return ("builtin",)
    path = user_track_dir() / f"{name}.json"
    if not NAME_PATTERN.match(name):
        raise _unknown(name)
    try:
        return _file_version(path)
    except TrackFileError:
        raise _unknown(name) from None


def list_tracks() -> list[TrackInfo]:
    """Every available track: built-ins, then readable user tracks by name."""
    infos = [TrackInfo.of(_builtin(n), "builtin") for n in builtin_names()]
    for path in _user_files().values():
        with contextlib.suppress(TrackFileError):
            infos.append(TrackInfo.of(_read_user_track(path), "user"))
    return infos


def _check_name(name: str) -> None:
    if not NAME_PATTERN.match(name):
        raise TrackError(
            f"track name {name!r} is not allowed: use letters, digits, '_', '-' or '.' "
            "(64 characters at most, starting with a letter or digit)"
        )
    if name in BUILTIN_DESIGNS:
        raise TrackError(f"track name {name!r} is taken by a built-in track; pass another name")


def import_track(path: str | Path, name: str | None = None, *, overwrite: bool = False) -> Track:
    """Read any supported track file and store it as ``<name>.json`` in the user directory.

    The file is written to a temporary name, read back and only then renamed, so a
    failed import leaves nothing behind. Raises :class:`TrackError` on a bad file, a
    name that clashes with a built-in, or an existing user track (unless ``overwrite``).
    """
    track = read_track(path, name)
    _check_name(track.name)
    folder = user_track_dir()
    target = folder / f"{track.name}.json"
    if target.exists() and not overwrite:
        raise TrackError(f"a user track named {track.name!r} already exists ({target})")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{track.name}.", suffix=".json", dir=folder)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write_document(track, tmp)
        read_document(tmp)
        tmp.chmod(0o644)
        tmp.replace(target)
    finally:
        tmp.unlink(missing_ok=True)
    return track

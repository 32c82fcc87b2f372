"""Finding tracks by name and importing user tracks into $SLIPSTREAM_HOME/tracks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tracks import catalog
from tracks.catalog import (
    TrackNotFoundError,
    builtin_names,
    get_track,
    import_track,
    list_tracks,
    user_track_dir,
)
from tracks.io import TrackFileError, read_document, write_document
from tracks.track import TrackError


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _user_files(home: Path) -> list[str]:
    folder = home / "tracks"
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def _copy_of_builtin(tmp_path: Path, name: str = "my_loop") -> Path:
    doc = tmp_path / f"{name}.json"
    write_document(get_track("beginner_loop"), doc)
    data = json.loads(doc.read_text())
    data["name"] = name
    doc.write_text(json.dumps(data))
    return doc


def test_user_dir_follows_env(home):
    assert user_track_dir() == home / "tracks"


def test_builtins_are_cached_and_directed():
    name = builtin_names()[0]
    assert get_track(name) is get_track(name)
    assert get_track(name, "cw").direction == "cw"
    assert get_track(name, "ccw") is get_track(name)


def test_unknown_name_lists_the_available_ones():
    with pytest.raises(TrackNotFoundError) as info:
        get_track("no_such_track")
    assert isinstance(info.value, TrackError)
    message = str(info.value)
    assert "no_such_track" in message
    assert all(name in message for name in builtin_names())


@pytest.mark.parametrize("name", ["../escape", "a/b", ""])
def test_path_like_names_are_not_found(name):
    with pytest.raises(TrackNotFoundError):
        get_track(name)


def test_import_round_trip_and_listing(tmp_path, home):
    track = import_track(_copy_of_builtin(tmp_path))
    assert track.name == "my_loop"
    assert _user_files(home) == ["my_loop.json"]
    loaded = get_track("my_loop", "cw")
    assert loaded.direction == "cw"
    assert loaded.length == pytest.approx(track.length)
    infos = {i.name: i for i in list_tracks()}
    assert infos["my_loop"].source == "user"
    assert infos["beginner_loop"].source == "builtin"
    with pytest.raises(TrackNotFoundError, match="tracks list") as unknown:
        get_track("zzz")
    assert "my_loop" not in str(unknown.value)  # another user's track is not shown


def test_import_with_new_name_and_no_silent_overwrite(tmp_path, home):
    path = _copy_of_builtin(tmp_path)
    assert import_track(path, name="renamed").name == "renamed"
    with pytest.raises(TrackError, match="already exists"):
        import_track(path, name="renamed")
    import_track(path, name="renamed", overwrite=True)
    assert _user_files(home) == ["renamed.json"]


@pytest.mark.parametrize("name", ["beginner_loop", "../evil", "has space"])
def test_bad_names_refused_and_nothing_written(tmp_path, home, name):
    with pytest.raises(TrackError):
        import_track(_copy_of_builtin(tmp_path), name=name)
    assert _user_files(home) == []


@pytest.mark.parametrize(
    ("filename", "content"),
    [
        ("broken.json", b"{not json"),
        ("short.json", b'{"name": "x", "centerline": [[0, 0]]}'),
        ("junk.npy", b"\x93NUMPY but not really"),
        ("notes.txt", b"hello"),
    ],
)
def test_bad_files_leave_nothing_behind(tmp_path, home, filename, content):
    path = tmp_path / filename
    path.write_bytes(content)
    with pytest.raises(TrackFileError):
        import_track(path)
    assert _user_files(home) == []


def test_wrong_shape_npy_refused(tmp_path, home):
    path = tmp_path / "three_cols.npy"
    np.save(path, np.zeros((10, 3)))
    with pytest.raises(TrackError, match="N x 6"):
        import_track(path)
    assert _user_files(home) == []


def test_failure_while_writing_leaves_nothing(tmp_path, home, monkeypatch):
    def half_write(track, path):
        Path(path).write_text('{"format": "slipstream-track", "name"')
        raise OSError("disk full")

    monkeypatch.setattr(catalog, "write_document", half_write)
    with pytest.raises(OSError, match="disk full"):
        import_track(_copy_of_builtin(tmp_path))
    assert _user_files(home) == []


def test_unreadable_user_file_is_skipped_in_listing(home):
    (home / "tracks").mkdir(parents=True)
    (home / "tracks" / "bad.json").write_text("[]")
    assert "bad" not in {i.name for i in list_tracks()}


@pytest.mark.realdata
def test_import_real_deepracer_file(home, shared_tracks):
    track = import_track(shared_tracks / "reinvent_base.npy")
    assert track.name == "reinvent_base"
    assert track.length == pytest.approx(17.7, abs=0.1)
    assert _user_files(home) == ["reinvent_base.json"]
    assert get_track("reinvent_base").length == pytest.approx(track.length)


def test_a_user_track_is_read_once_per_version_of_its_file(tmp_path, home, monkeypatch):
    """Repeated lookups reuse the checked geometry; a rewritten file is read again."""
    import_track(_copy_of_builtin(tmp_path))
    reads = []

    def counting_read(path):
        reads.append(path)
        return read_document(path)

    monkeypatch.setattr(catalog, "read_document", counting_read)
    first = [get_track("my_loop", direction) for direction in ("ccw", "cw", None) * 20]
    assert len(reads) == 1 and first[0].name == "my_loop"
    wider = json.loads((home / "tracks" / "my_loop.json").read_text())
    wider["display_name"] = "My loop, renamed"
    (home / "tracks" / "my_loop.json").write_text(json.dumps(wider))
    assert get_track("my_loop").display_name == "My loop, renamed"
    assert len(reads) == 2


def test_the_user_track_cache_is_bounded(tmp_path, home):
    catalog._read_version.cache_clear()
    for i in range(catalog.USER_TRACK_CACHE_SIZE + 8):
        import_track(_copy_of_builtin(tmp_path, f"loop{i}"))
        get_track(f"loop{i}")
    assert catalog._read_version.cache_info().currsize == catalog.USER_TRACK_CACHE_SIZE


def test_a_broken_user_track_names_the_track_not_the_server_path(home):
    folder = home / "tracks"
    folder.mkdir(parents=True)
    (folder / "broken.json").write_text('{"name": "broken", "centerline": [[0, 0]]')
    (folder / "crossed.json").write_text(json.dumps({"name": "crossed", "centerline": 7}))
    for name in ("broken", "crossed"):
        with pytest.raises(TrackError) as err:
            get_track(name)
        message = str(err.value)
        assert f"'{name}'" in message and str(home) not in message and ".json" not in message

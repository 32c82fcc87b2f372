"""``slipstream tracks`` commands, run through Typer's test runner."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from tracks.catalog import builtin_names, get_track
from tracks.cli import app
from tracks.io import write_document
from tracks.raceline import CarLimits

runner = CliRunner()


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _ok(*args: str):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result


def _fails(*args: str):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    assert result.stdout == ""
    return result.stderr


def test_list_table_and_json():
    text = _ok("list").stdout
    assert "beginner_loop" in text and "builtin" in text
    rows = json.loads(_ok("list", "--json").stdout)
    assert [r["name"] for r in rows] == builtin_names()
    assert {"name", "display_name", "length", "width", "direction", "source"} <= set(rows[0])


def test_show_json_in_both_directions():
    ccw = json.loads(_ok("show", "beginner_loop", "--json").stdout)
    cw = json.loads(_ok("show", "beginner_loop", "--direction", "cw", "--json").stdout)
    assert (ccw["direction"], cw["direction"]) == ("ccw", "cw")
    assert ccw["length"] == cw["length"]
    assert ccw["source"] == "builtin"


def test_show_writes_png_with_racing_line(tmp_path):
    png = tmp_path / "track.png"
    out = _ok("show", "hairpin_hollow", "--png", str(png), "--raceline").stdout
    assert "lap time" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unknown_track_is_one_clear_error():
    for command in ("show", "raceline"):
        err = _fails(command, "atlantis")
        assert "unknown track 'atlantis'" in err
        assert "beginner_loop" in err


def test_bad_import_leaves_nothing(tmp_path, home):
    bad = tmp_path / "bad.json"
    bad.write_text("{oops")
    assert "not valid JSON" in _fails("import", str(bad))
    assert "no such file" in _fails("import", str(tmp_path / "missing.npy"))
    assert not (home / "tracks").exists() or not any((home / "tracks").iterdir())


def test_import_refuses_builtin_name(tmp_path):
    doc = tmp_path / "copy.yaml"
    write_document(get_track("grand_tour"), doc)
    assert "built-in" in _fails("import", str(doc))
    imported = json.loads(_ok("import", str(doc), "--name", "my_tour", "--json").stdout)
    assert imported["name"] == "my_tour" and imported["source"] == "user"
    assert "my_tour" in _ok("list").stdout


@pytest.mark.realdata
def test_import_real_file_then_raceline(home, shared_tracks):
    _ok("import", str(shared_tracks / "reinvent_base.npy"))
    assert (home / "tracks" / "reinvent_base.json").is_file()
    doc = json.loads(_ok("raceline", "reinvent_base", "--json").stdout)
    assert doc["track"] == "reinvent_base"
    assert doc["length"] == pytest.approx(17.7, abs=0.1)
    top = CarLimits().max_speed
    assert doc["length"] / top < doc["lap_time"] < doc["centerline_lap_time"]
    assert doc["limits"]["max_speed"] == top
    text = _ok("raceline", "reinvent_base", "--direction", "cw").stdout
    assert "physical-limit lap time" in text


def test_import_of_an_npy_claiming_a_huge_shape_is_a_track_file_error(tmp_path, home):
    """608 bytes whose header claims (2e9, 6) floats: an error line, no traceback, no file."""
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2000000000, 6), }"
    header += " " * (118 - len(header) - 1) + "\n"
    data = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
    bomb = tmp_path / "bomb.npy"
    bomb.write_bytes(data + bytes(608 - len(data)))
    err = _fails("import", str(bomb))
    assert "bomb.npy" in err and "at most 2000" in err
    assert not (home / "tracks").exists() or not list((home / "tracks").iterdir())

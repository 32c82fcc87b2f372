"""What the create-a-model page is offered (``/api/garage/catalogue``), the track thumbnails
it shows, and deleting an ended training job, against a real server."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info

from agents.action_spaces import parse_action_space_spec
from agents.options import settings_from_options
from agents.rewards import bundled_samples
from arena.sensors_spec import check_sensors
from league.models import TrainingEvent, TrainingJob, utcnow
from tests.league.conftest import League
from tracks.catalog import builtin_names, get_track


def test_the_catalogue_says_what_training_accepts(league: League) -> None:
    with league.client() as anyone:
        answer = anyone.get("/api/garage/catalogue")
        again = anyone.get(
            "/api/garage/catalogue", headers={"If-None-Match": answer.headers["etag"]}
        )
    assert answer.status_code == 200 and again.status_code == 304
    found = answer.json()

    tracks = {t["name"]: t for t in found["tracks"]}
    assert list(tracks) == builtin_names()
    speedway = get_track("slipstream_speedway")
    row = tracks["slipstream_speedway"]
    assert row["width"] == pytest.approx(speedway.width, abs=1e-3)
    assert row["length"] == pytest.approx(speedway.length, abs=1e-3)
    # the physical limit is a lap at DeepRacer's top speed or slower
    assert row["physical_limit_lap_s"] >= speedway.length / found["action_space"]["max_speed"]

    sensors = found["sensors"]
    for combination in sensors["combinations"]:
        assert list(check_sensors(combination)) == combination
    with pytest.raises(ValueError):
        check_sensors(["camera", "stereo"])
    assert ["camera", "stereo"] not in sensors["combinations"]

    for form in ("console:30:5:1.5:2", "continuous:-30:30:0.5:4", "list:-15/1.0,15/1.0"):
        parse_action_space_spec(form)  # the forms the page builds are what training takes
    default = found["action_space"]["console_default"]
    assert default == {
        "max_steering_deg": 30.0, "steering_granularity": 5, "max_speed": 0.8,
        "speed_granularity": 2,
    }  # fmt: skip

    hyper = {h["name"]: h for h in found["hyperparameters"]}
    assert hyper["batch_size"]["default"] == 64 and hyper["batch_size"]["max"] == 4096
    assert hyper["loss_type"]["choices"] == ["huber", "mean squared error"]
    assert all(h["help"] for h in found["hyperparameters"])
    assert {s["name"] for s in found["reward_samples"]} == set(bundled_samples())
    assert next(r for r in found["recipes"] if r["name"] == "head_to_model")["needs_parent"]
    assert found["limits"]["max_minutes"] == league.settings.training_max_minutes
    own = {r["name"]: {s["option"]: s for s in r["settings"]} for r in found["race_types"]}
    assert own["time_trial"] == {} and set(own["object_avoidance"]) == {"boxes"}
    bots = own["head_to_bot"]
    assert (bots["bots"]["default"], bots["bots"]["min"], bots["bots"]["max"]) == (3, 1, 6)
    assert bots["bot_speed"]["help"] == "the bots' speed in m/s"  # the field's label
    # each is a training option, taken at its range's ends and refused past them
    for race_type, settings in own.items():
        for option, spec in settings.items():
            ends = {option: spec.get("max", spec["default"])}
            settings_from_options({"race_type": race_type, **ends})
            if "max" in spec:
                with pytest.raises(ValueError, match=option):
                    settings_from_options({"race_type": race_type, option: spec["max"] + 1})


def test_track_thumbnails_are_svg_and_unknown_tracks_404(league: League) -> None:
    with league.client() as anyone:
        picture = anyone.get("/api/tracks/hairpin_hollow/thumbnail.svg", params={"direction": "cw"})
        missing = anyone.get("/api/tracks/no_such_track/thumbnail.svg")
    assert picture.status_code == 200
    assert picture.headers["content-type"].startswith("image/svg+xml")
    assert picture.text.lstrip().startswith("<svg")
    assert missing.status_code == 404 and "no_such_track" in missing.json()["detail"]


def _job(league: League, status: str) -> int:
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids["alice"], name=f"delete-{status}", status=status,
            spec={"options": {}}, reward_source="", minutes=1, finished_at=utcnow(),
        )  # fmt: skip
        session.add(job)
        session.flush()
        session.add(TrainingEvent(job_id=job.id, kind="log", data={"line": "hello"}))
        session.commit()
        return job.id


def test_only_an_ended_job_is_deleted_and_only_by_its_owner(league: League) -> None:
    running, ended = _job(league, "running"), _job(league, "done")
    with league.client("alice") as alice, league.client("bob") as bob:
        refused = alice.delete(f"/api/training-jobs/{running}")
        stranger = bob.delete(f"/api/training-jobs/{ended}")
        deleted = alice.delete(f"/api/training-jobs/{ended}")
        gone = alice.get(f"/api/training-jobs/{ended}")
    assert refused.status_code == 409 and "stop it first" in refused.json()["detail"]
    assert stranger.status_code == 404
    assert deleted.status_code == 204 and gone.status_code == 404
    with league.sessions() as session:
        assert session.get(TrainingJob, running) is not None
        left = session.query(TrainingEvent).filter_by(job_id=ended).count()
    assert left == 0


def test_the_server_does_its_blas_work_on_one_thread(league: League) -> None:
    """A racing line for the catalogue waits on threaded BLAS when training jobs load the
    host (50-107 s instead of 2-4, benchmarks/RESULTS.md): the running server holds every
    BLAS library its process has loaded to one thread."""
    with league.client() as anyone:
        assert anyone.get("/api/garage/catalogue").status_code == 200
    blas = [info for info in threadpool_info() if info["user_api"] == "blas"]
    assert blas and all(info["num_threads"] == 1 for info in blas)

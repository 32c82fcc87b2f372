"""A model is judged by how it races: faults on real frames cost that car its race, not the
round; a model that keeps breaking races is suspended from the event, its owner told why.

The hostile models are camera policies built here with ``onnx.helper``. Each computes how
rough the frame is (the mean difference between neighbouring pixels): random frames, which
validation feeds, are rough; a real camera frame of the track is smooth. On smooth frames
one model outputs -inf logits and the other runs a hundred square-root passes over a
million floats (a work size chosen by the frame, hidden from shape inference), so both pass
validation and misbehave only once they drive.
"""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from onnx import TensorProto, helper, numpy_helper
from sqlalchemy import select

import arena
from arena.race import RaceResult, run_race
from league.jobs.evaluation import CarPlan, RacePlan, policies
from league.jobs.scheduler import due_rounds
from league.jobs.worker import Worker
from league.models import Entry, Job, Race
from submissions import validate
from tests.league.conftest import League, start_league
from tests.league.helpers import create_event, enter, round_job, upload
from tests.league.page_text import read_page
from tests.submissions.test_support import pack_bytes

N_ACTIONS = 10
HEIGHT, WIDTH = 120, 160
BUDGET_MS = 20.0


def _t(name: str, value: np.ndarray):
    return numpy_helper.from_array(np.asarray(value), name)


def _smooth_gate() -> tuple[list, list]:
    """camera -> ``gate0`` [B] (1 on a smooth, real frame; 0 on noise) and ``logits``."""
    nodes = [
        helper.make_node("Cast", ["camera"], ["x"], to=TensorProto.FLOAT),
        helper.make_node("Slice", ["x", "s1", "e1", "ax2"], ["right"]),
        helper.make_node("Slice", ["x", "s0", "e0", "ax2"], ["left"]),
        helper.make_node("Sub", ["right", "left"], ["diff"]),
        helper.make_node("Abs", ["diff"], ["step"]),
        helper.make_node("ReduceMean", ["step"], ["rough"], axes=[1, 2, 3], keepdims=0),
        helper.make_node("Sub", ["threshold", "rough"], ["below"]),
        helper.make_node("Relu", ["below"], ["smooth"]),
        helper.make_node("Mul", ["smooth", "huge"], ["steep"]),
        helper.make_node("Min", ["steep", "one"], ["gate0"]),
        helper.make_node("Unsqueeze", ["gate0", "ax1"], ["gate"]),
        helper.make_node("ReduceMean", ["x"], ["bright"], axes=[1, 2, 3], keepdims=0),
        helper.make_node("Unsqueeze", ["bright", "ax1"], ["bright1"]),
        helper.make_node("MatMul", ["bright1", "row"], ["logits"]),
    ]
    inits = [
        _t("s1", np.array([1], np.int64)),
        _t("e1", np.array([WIDTH], np.int64)),
        _t("s0", np.array([0], np.int64)),
        _t("e0", np.array([WIDTH - 1], np.int64)),
        _t("ax2", np.array([2], np.int64)),
        _t("ax1", np.array([1], np.int64)),
        _t("threshold", np.array(20.0, np.float32)),
        _t("huge", np.array(1e6, np.float32)),
        _t("one", np.array(1.0, np.float32)),
        _t("row", np.linspace(-0.01, 0.01, N_ACTIONS, dtype=np.float32)[None, :]),
    ]
    return nodes, inits


def _archive(nodes: list, inits: list) -> bytes:
    graph = helper.make_graph(
        nodes,
        "policy",
        [helper.make_tensor_value_info("camera", TensorProto.UINT8, ["batch", HEIGHT, WIDTH, 1])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["batch", N_ACTIONS])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return pack_bytes(model, sensors=("camera",))


def inf_on_real_frames() -> bytes:
    """Logits + log(1 - gate): finite on noise, -inf on every real frame."""
    nodes, inits = _smooth_gate()
    nodes += [
        helper.make_node("Sub", ["one", "gate"], ["rest"]),
        helper.make_node("Log", ["rest"], ["cliff"]),
        helper.make_node("Add", ["logits", "cliff"], ["out"]),
    ]
    return _archive(nodes, inits)


def slow_on_real_frames(doublings: int = 10, passes: int = 100) -> bytes:
    """Fast on noise; on real frames ``passes`` square roots over ``2**doublings`` x 1024
    floats a step."""
    nodes, inits = _smooth_gate()
    nodes += [
        helper.make_node("Mul", ["gate0", "span"], ["extra"]),
        helper.make_node("Add", ["extra", "one"], ["endf"]),
        helper.make_node("ReduceMax", ["endf"], ["endm"], keepdims=1),
        helper.make_node("Cast", ["endm"], ["end"], to=TensorProto.INT64),
        helper.make_node("Slice", ["ones", "s0", "end"], ["v0"]),
    ]
    for i in range(doublings):
        nodes.append(helper.make_node("Concat", [f"v{i}", f"v{i}"], [f"v{i + 1}"], axis=0))
    previous = f"v{doublings}"
    for i in range(passes):
        nodes.append(helper.make_node("Sqrt", [previous], [f"q{i}"]))
        previous = f"q{i}"
    nodes += [
        helper.make_node("ReduceMean", [previous], ["total"], keepdims=1),
        helper.make_node("Mul", ["total", "zero"], ["nothing"]),
        helper.make_node("Add", ["logits", "nothing"], ["out"]),
    ]
    inits += [
        _t("span", np.array(1023.0, np.float32)),
        _t("ones", np.ones(1024, np.float32)),
        _t("zero", np.array(0.0, np.float32)),
    ]
    return _archive(nodes, inits)


def _gate_scalar(nodes: list, scale: float, name: str) -> str:
    """Append nodes for ``int64 [round(max(gate0) * scale)]``; return its name."""
    nodes += [
        helper.make_node("ReduceMax", ["gate0"], [f"{name}_max"], keepdims=1),
        helper.make_node("Mul", [f"{name}_max", f"{name}_scale"], [f"{name}_f"]),
        helper.make_node("Cast", [f"{name}_f"], [name], to=TensorProto.INT64),
    ]
    return name


def unrunnable_on_real_frames() -> bytes:
    """Reshapes its logits to ``(-1, 10 + 3 * gate)``: fine on noise; on a real frame ten
    values a row cannot fill rows of 13, and onnxruntime raises."""
    nodes, inits = _smooth_gate()
    extra = _gate_scalar(nodes, 3.0, "extra")
    nodes += [
        helper.make_node("Add", [extra, "width"], ["columns"]),
        helper.make_node("Concat", ["minus_one", "columns"], ["shape"], axis=0),
        helper.make_node("Reshape", ["logits", "shape"], ["out"]),
    ]
    inits += [
        _t("extra_scale", np.array([3.0], np.float32)),
        _t("width", np.array([N_ACTIONS], np.int64)),
        _t("minus_one", np.array([-1], np.int64)),
    ]
    return _archive(nodes, inits)


def narrow_on_real_frames() -> bytes:
    """Slices its logits to ``10 - 5 * gate`` columns: ten on noise, five on a real frame."""
    nodes, inits = _smooth_gate()
    cut = _gate_scalar(nodes, 5.0, "cut")
    nodes += [
        helper.make_node("Sub", ["width", cut], ["end"]),
        helper.make_node("Slice", ["logits", "s0", "end", "ax1"], ["out"]),
    ]
    inits += [
        _t("cut_scale", np.array([5.0], np.float32)),
        _t("width", np.array([N_ACTIONS], np.int64)),
    ]
    return _archive(nodes, inits)


def _race_with_a_bot(
    models: tuple[bytes, bytes], time_limit_s: float, step_budget_ms: float | None = None
) -> tuple[list[str], RaceResult]:
    """A one-lap camera race of two model files and a pursuit bot, guarded as the league's
    races are; the car names (models first) and the result."""
    config = arena.make_config(
        race_type="head_to_model",
        sensors=("camera",),
        num_cars=3,
        laps=1,
        time_limit_s=time_limit_s,
    )
    names = [c.name for c in config.cars]
    cars = (
        CarPlan(names[0], 1, model=models[0]),
        CarPlan(names[1], 2, model=models[1]),
        CarPlan(names[2], None, bot="pursuit"),
    )
    plan = RacePlan(config, cars, step_budget_ms=step_budget_ms)
    return names, run_race(plan.config, policies(plan), guard=plan.guard())


def test_a_model_onnxruntime_cannot_run_or_that_narrows_its_output_is_out() -> None:
    hostile = (unrunnable_on_real_frames(), narrow_on_real_frames())
    assert all(validate(model).ok for model in hostile)  # both pass on random frames
    names, result = _race_with_a_bot(hostile, time_limit_s=8.0)
    unrunnable, narrow, bot = (result.car(n) for n in names)
    assert unrunnable.status == "dnf" and unrunnable.dnf_reason is not None
    assert unrunnable.dnf_reason.startswith(
        f"model fault: car {names[0]}: onnxruntime failed at step 1 in a Reshape node:"
    )
    assert "cannot be reshaped" in unrunnable.dnf_reason
    assert "[ONNXRuntimeError]" not in unrunnable.dnf_reason
    assert "/onnxruntime_src" not in unrunnable.dnf_reason
    assert (narrow.status, narrow.dnf_reason) == (
        "dnf",
        f"model fault: car {names[1]}: the model output shape (1, 5) at step 1, not (1, 10)",
    )
    assert bot.dnf_reason is None and bot.distance > 3.0


def test_a_car_that_faults_on_real_frames_is_out_and_the_other_races_on() -> None:
    hostile = (inf_on_real_frames(), slow_on_real_frames())
    names, result = _race_with_a_bot(hostile, time_limit_s=12.0, step_budget_ms=BUDGET_MS)
    inf, slow, bot = (result.car(n) for n in names)
    assert (inf.status, inf.dnf_reason) == (
        "dnf",
        f"model fault: car {names[0]}: the model output NaN or inf at step 1",
    )
    assert slow.status == "dnf" and slow.dnf_reason is not None
    assert slow.dnf_reason.startswith("too slow: its fastest of 10 steps took")
    assert slow.dnf_reason.endswith(f"over the budget of {BUDGET_MS:g} ms a step")
    assert bot.dnf_reason is None and bot.distance > 5.0  # it raced on, the others gone
    assert result.duration > 5.0


@pytest.fixture(scope="module")
def faults_league(database, tmp_path_factory: pytest.TempPathFactory):
    """A league whose head-to-model rounds race three cars, one race per model a round."""
    folder = tmp_path_factory.mktemp("faults") / "data"
    yield from start_league(database, folder, round_races_per_model=1, round_max_cars=3)


def _upload_bytes(league: League, who: str, data: bytes, name: str) -> int:
    with league.client(who) as client:
        response = client.post("/api/models", files={"file": (f"{name}.zip", data)})
    assert response.status_code == 201, response.text  # validation passes both
    return response.json()["id"]


def _run_round(league: League, worker: Worker, when) -> list[int]:
    with league.sessions() as session:
        assert due_rounds(session, when, league.settings) > 0
    while worker.run_once():
        pass
    with league.sessions() as session:
        number = session.scalar(select(Job.round).order_by(Job.id.desc()).limit(1))
        return list(session.scalars(select(Job.id).where(Job.round == number)))


def test_hostile_models_lose_their_races_not_the_rounds_and_are_suspended(
    faults_league: League, tmp_path: Path
) -> None:
    league = faults_league
    event = create_event(
        league,
        name="Faults Cup",
        race_type="head_to_model",
        laps=1,
        time_limit_s=10.0,
        round_interval_s=60,
    )
    good = enter(league, "alice", event["id"], upload(league, "alice", seed=3)["id"])
    nan_id = _upload_bytes(league, "bob", inf_on_real_frames(), "cliff")
    slow_id = _upload_bytes(league, "admin", slow_on_real_frames(), "treacle")
    bad = enter(league, "bob", event["id"], nan_id)["entry_id"]
    slow = enter(league, "admin", event["id"], slow_id)["entry_id"]
    settings = league.settings.model_copy(update={"race_step_budget_ms": BUDGET_MS})
    worker = Worker(settings, "faults")
    with league.sessions() as session:
        due = session.get_one(Entry, good["entry_id"]).created_at

    jobs: list[int] = []
    for number in range(3):  # one race a round; the third fault suspends
        jobs += _run_round(league, worker, due + timedelta(seconds=61 * (number + 1)))
    with league.sessions() as session:
        states = {j.status for j in session.scalars(select(Job).where(Job.id.in_(jobs)))}
        races = session.scalars(select(Race).where(Race.job_id.in_(jobs))).all()
        assert states == {"done"} and len(races) == len(jobs) == 3
        race_ids = [r.id for r in races]
        for race in races:
            cars = {c.entry_id: c for c in race.cars}
            assert cars[good["entry_id"]].dnf_reason is None
            assert cars[good["entry_id"]].distance_m > 1.0
            assert "NaN or inf" in cars[bad].dnf_reason
            assert cars[slow].dnf_reason.startswith("too slow")

    with league.client() as client:  # the race's API result and its page say why
        shown = client.get(f"/api/races/{race_ids[0]}").json()
        page = read_page(client.get(f"/races/{race_ids[0]}").text)
    reasons = shown["summary"]["dnf_reasons"]
    shown_cars = {c["entry_id"]: c for c in shown["cars"]}
    assert {shown_cars[e]["status"] for e in (bad, slow)} == {"dnf"}
    assert "NaN or inf" in shown_cars[bad]["dnf_reason"]
    assert shown_cars[good["entry_id"]]["dnf_reason"] is None
    assert "NaN or inf" in reasons[f"entry{bad}"]
    assert "Out of the race" in page.headings
    assert f"entry{bad} : model fault: car entry{bad}: the model output NaN or inf" in page.text
    assert f"entry{slow} : too slow: its fastest of 10 steps took" in page.text

    with league.client("bob") as client:  # the owner reads the suspension
        (mine,) = client.get(f"/api/events/{event['id']}/entries").json()
    assert mine["suspended"] and mine["fault_dnfs"] == 3
    assert mine["suspension"].startswith(f"Model {nan_id} was suspended from event")
    assert "taken out of 3 of the event's races" in mine["suspension"]

    later = _run_round(league, worker, due + timedelta(seconds=61 * 4))
    with league.sessions() as session:  # the valid model races on without them
        (job,) = session.scalars(select(Job).where(Job.id.in_(later)))
        assert job.status == "done"
        assert {s.get("entry_id") for s in job.lineup} == {good["entry_id"], None}
        queued = round_job(session, event["id"], [good["entry_id"], bad], seed=99)
    while worker.run_once():  # a grid queued before the suspension races without it
        pass
    with league.sessions() as session:
        assert session.get_one(Job, queued).status == "done"
        race = session.scalar(select(Race).where(Race.job_id == queued))
        assert {c.entry_id for c in race.cars} == {good["entry_id"], None}
        (bot,) = (c for c in race.cars if c.entry_id is None)
        assert bot.laps == 1  # the event's round_bot, the racer (at 0.8 m/s pursuit makes 8 m)

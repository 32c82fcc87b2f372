// Race page: load the race, its trace and the track geometry, then animate the cars
// (play / pause, 1x-2x-4x, scrub), list lap and sector splits, mark incidents, overtakes and
// contacts (with the car at fault), and optionally compare a car's best lap with the event
// leader's as a ghost.
"use strict";

const COLORS = ["#e6194b", "#2f9bff", "#ffd21f", "#2ecc71", "#ff8a1f", "#b05cff", "#2ee6e6", "#ff5ccd"];
const TRAIL_S = 1.5;
const root = document.getElementById("replay");

const player = {
  cars: [],
  bots: [],
  botDt: 1 / 15,
  obstacles: [],
  marks: [],
  time: 0,
  duration: 0,
  speed: 1,
  playing: false,
  ghost: null,
  view: null,
};

function carLabel(car) {
  return car.alias || car.car_name;
}

async function loadJson(path) {
  const answer = await Slip.api(path);
  if (!answer.ok) throw new Error((answer.body && answer.body.detail) || `${path}: ${answer.status}`);
  return answer.body;
}

// ---------------------------------------------------------------- the normal replay
function drawRace() {
  const view = player.view;
  view.drawTrack();
  for (const box of player.obstacles) view.drawObstacle(box);
  for (const car of player.cars) {
    for (const incident of car.incidents) if (incident.t <= player.time) view.drawMarker(incident);
  }
  for (const mark of shownMarks()) view.drawRaceMark(mark, mark.color, mark.label);
  const step = Math.min(Math.floor(player.time / player.botDt), player.bots.length - 1);
  if (step >= 0) {
    for (const bot of player.bots[step]) view.drawCar({ x: bot[0], y: bot[1], yaw: bot[2] }, "#9aa0a6", { label: "bot" });
  }
  for (const car of player.cars) {
    view.drawTrail(trail(car.trace, player.time), car.color);
  }
  for (const car of player.cars) {
    car.pose = Laps.poseAt(car.trace, player.time);
    view.drawCar(car.pose, car.color, { label: carLabel(car) });
  }
}

// ---------------------------------------------------------------- overtakes and contacts
// The race's events placed where the car they are about was: overtakes in the passing car's
// colour, contacts in the colour of the car at fault (grey when nobody was), labelled.
function raceMarks(events, cars) {
  const byName = Object.fromEntries(cars.map((c) => [c.car_name, c]));
  return events
    .filter((e) => byName[e.car])
    .map((e) => {
      const car = byName[e.car];
      const pose = Laps.poseAt(car.trace, e.t);
      const blamed = e.kind === "overtake" || e.at_fault;
      return Object.assign({}, e, {
        x: pose.x,
        y: pose.y,
        color: blamed ? car.color : "#9aa0a6",
        label: e.kind === "contact" && e.at_fault ? `${carLabel(car)} at fault` : null,
      });
    });
}

function shownMarks() {
  return player.marks.filter((m) => m.t <= player.time);
}

function nameOf(name) {
  const car = player.cars.find((c) => c.car_name === name);
  return car ? carLabel(car) : name;
}

function eventText(e) {
  const at = `at ${e.t.toFixed(1)} s`;
  if (e.kind === "overtake") return `${nameOf(e.car)} passed ${nameOf(e.other)} ${at}`;
  if (e.at_fault) return `contact ${nameOf(e.car)} → ${nameOf(e.other)} ${at}: ${nameOf(e.car)} at fault`;
  return `contact ${nameOf(e.car)} – ${nameOf(e.other)} ${at}: nobody at fault`;
}

function eventList(marks) {
  if (!marks.length) return [Slip.el("li", { class: "muted" }, "No overtakes or contacts.")];
  return marks.map((m) =>
    Slip.el(
      "li",
      { class: `race-event ${m.kind}`, "data-kind": m.kind, "data-car": m.car, "data-at-fault": String(m.at_fault) },
      Slip.el("span", { class: "swatch", style: `background:${m.color}` }),
      seekButton(eventText(m), Math.max(0, m.t - 1)),
    ),
  );
}

function trail(trace, time) {
  const last = Laps.indexAt(trace, time);
  const first = Math.max(0, Laps.indexAt(trace, time - TRAIL_S));
  const points = [];
  for (let i = first; i <= last; i++) points.push([trace.x[i], trace.y[i]]);
  return points;
}

// ---------------------------------------------------------------- the ghost comparison
function drawGhost() {
  const g = player.ghost;
  const view = player.view;
  view.drawTrack();
  const leaderPose = Laps.poseAt(g.leaderTrace, g.leaderLap.start + Math.min(player.time, g.leaderTime));
  const minePose = Laps.poseAt(g.car.trace, g.lap.start + Math.min(player.time, g.lapTime));
  view.drawCar(leaderPose, "#ffffff", { alpha: 0.45, label: "leader (ghost)" });
  view.drawCar(minePose, g.car.color, { label: carLabel(g.car) });
  g.car.pose = minePose;
  const progress = Laps.progressAt(g.car.trace, g.lap, g.lap.start + Math.min(player.time, g.lapTime));
  const leaderAt = Laps.timeAtProgress(g.leaderTrace, g.leaderLap, progress);
  const gap = leaderAt === null ? "" : `  gap ${formatGap(Math.min(player.time, g.lapTime) - leaderAt)}`;
  document.getElementById("ghost-info").textContent =
    `lap ${Slip.ms(g.lapTime * 1000)} vs leader ${Slip.ms(g.leaderTime * 1000)}${gap}`;
}

function formatGap(seconds) {
  return (seconds >= 0 ? "+" : "−") + Math.abs(seconds).toFixed(3) + " s";
}

// The leader of the event: rank 1's car in its best race, and that car's trace.
async function loadLeader(eventId, traces) {
  const board = await loadJson(`/api/events/${eventId}/leaderboard`);
  const top = board.rows.find((r) => r.rank === 1 && r.race_id);
  if (!top) return null;
  const race = await loadJson(`/api/races/${top.race_id}`);
  const car = race.cars.find((c) => c.model_id === top.model_id);
  if (!car) return null;
  const trace = traces[top.race_id] || (await loadJson(`/api/races/${top.race_id}/trace`)).trace;
  const lap = Laps.bestLap(Laps.laps(trace[car.car_name]));
  return lap ? { trace: trace[car.car_name], lap, alias: top.alias } : null;
}

async function setGhost(enabled) {
  const info = document.getElementById("ghost-info");
  if (!enabled) {
    player.ghost = null;
    info.textContent = "vs the event leader's best lap";
    setDuration(player.raceDuration);
    return;
  }
  const car = player.cars[Number(document.getElementById("ghost-car").value)];
  const lap = Laps.bestLap(car.laps);
  if (!player.leader) player.leader = await loadLeader(root.dataset.eventId, { [root.dataset.raceId]: player.traces });
  if (!lap || !player.leader) {
    info.textContent = !lap ? "this car has no completed lap" : "the event has no leader with a lap yet";
    document.getElementById("ghost-on").checked = false;
    return;
  }
  player.ghost = {
    car,
    lap,
    lapTime: lap.end - lap.start,
    leaderTrace: player.leader.trace,
    leaderLap: player.leader.lap,
    leaderTime: player.leader.lap.end - player.leader.lap.start,
  };
  setDuration(Math.max(player.ghost.lapTime, player.ghost.leaderTime));
}

// ---------------------------------------------------------------- controls and loop
function setDuration(duration) {
  player.duration = duration;
  player.time = 0;
  render();
}

function render() {
  if (player.ghost) drawGhost();
  else drawRace();
  const scrub = document.getElementById("scrub");
  scrub.value = String(Math.round((1000 * player.time) / (player.duration || 1)));
  document.getElementById("clock").textContent =
    `${player.time.toFixed(2)} / ${player.duration.toFixed(2)} s`;
  updateTelemetry();
  root.dataset.time = player.time.toFixed(3);
}

function updateTelemetry() {
  const g = player.ghost;
  for (const car of player.cars) {
    const node = document.getElementById(`telemetry-${car.index}`);
    if (g && car !== g.car) {
      node.textContent = "";
      continue;
    }
    const time = g ? g.lap.start + Math.min(player.time, g.lapTime) : player.time;
    const i = Math.max(0, Laps.indexAt(car.trace, time));
    const status = car.trace.status[i].replace("_", " ");
    node.textContent = `${car.trace.speed[i].toFixed(2)} m/s · steer ${Math.round(car.trace.steer[i])}° · ${status}`;
  }
}

let lastFrame = null;
function frame(now) {
  if (!player.playing) {
    lastFrame = null;
    return;
  }
  if (lastFrame !== null) player.time += ((now - lastFrame) / 1000) * player.speed;
  lastFrame = now;
  if (player.time >= player.duration) {
    player.time = player.duration;
    setPlaying(false);
  }
  render();
  if (player.playing) window.requestAnimationFrame(frame);
}

function setPlaying(playing) {
  if (playing && player.time >= player.duration) player.time = 0;
  player.playing = playing;
  root.dataset.playing = String(playing);
  document.getElementById("play").textContent = playing ? "❚❚ Pause" : "▶ Play";
  if (playing) window.requestAnimationFrame(frame);
}

function wireControls() {
  document.getElementById("play").addEventListener("click", () => setPlaying(!player.playing));
  for (const button of document.querySelectorAll(".speed")) {
    button.addEventListener("click", () => {
      player.speed = Number(button.dataset.speed);
      document.querySelectorAll(".speed").forEach((b) => b.classList.toggle("active", b === button));
    });
  }
  document.getElementById("scrub").addEventListener("input", (event) => {
    player.time = (Number(event.target.value) / 1000) * player.duration;
    render();
  });
  document.getElementById("ghost-on").addEventListener("change", (event) => setGhost(event.target.checked));
  document.getElementById("ghost-car").addEventListener("change", () => {
    if (document.getElementById("ghost-on").checked) setGhost(true);
  });
}

// ---------------------------------------------------------------- side panel
function seekButton(label, time) {
  const button = Slip.el("button", { type: "button", class: "link" }, label);
  button.addEventListener("click", () => {
    if (player.ghost) return;
    player.time = time;
    render();
  });
  return button;
}

function carPanel(car) {
  const sec = (s) => (s === undefined ? "—" : s.toFixed(3));
  const lapRows = car.laps.map((lap) =>
    Slip.el(
      "tr",
      {},
      Slip.el("td", {}, seekButton(String(lap.number), lap.start)),
      ...[0, 1, 2].map((k) => Slip.el("td", {}, sec(lap.sectors[k]))),
      Slip.el("td", { class: "score" }, lap.end === null ? "—" : sec(lap.end - lap.start)),
    ),
  );
  const laps = Slip.el(
    "table",
    { class: "splits" },
    Slip.el("thead", {}, Slip.el("tr", {}, ...["Lap", "S1", "S2", "S3", "Lap time"].map((h) => Slip.el("th", {}, h)))),
    Slip.el("tbody", {}, ...lapRows),
  );
  const incidents = car.incidents.map((inc) =>
    seekButton(`${inc.kind === "crash" ? "crash" : "off track"} at ${inc.t.toFixed(1)} s`, Math.max(0, inc.t - 1)),
  );
  const result = car.result;
  const gap = result.gap_to_winner_ms === null ? "" : ` · gap +${(result.gap_to_winner_ms / 1000).toFixed(3)} s`;
  const racing =
    `overtakes ${result.overtakes} · overtaken ${result.times_overtaken} · ` +
    `at-fault collisions ${result.at_fault_collisions} · laps led ${result.laps_led}${gap}`;
  return Slip.el(
    "div",
    { class: "car-card", "data-car": car.car_name },
    Slip.el("h3", {}, Slip.el("span", { class: "swatch", style: `background:${car.color}` }), `P${result.finish_position} ${carLabel(car)}`),
    Slip.el("p", { class: "muted" }, `${result.status} · ${result.laps} lap(s) · total ${Slip.ms(result.total_ms)} · penalties ${Slip.ms(result.penalty_ms)}`),
    Slip.el("p", { class: "racing" }, racing),
    Slip.el("p", { class: "telemetry", id: `telemetry-${car.index}` }),
    laps,
    incidents.length ? Slip.el("p", { class: "incidents" }, ...incidents) : null,
  );
}

// ---------------------------------------------------------------- start
async function start() {
  const raceId = root.dataset.raceId;
  const direction = encodeURIComponent(root.dataset.direction);
  const [race, data, geometry] = await Promise.all([
    loadJson(`/api/races/${raceId}`),
    loadJson(`/api/races/${raceId}/trace`),
    loadJson(`/api/tracks/${encodeURIComponent(root.dataset.track)}?direction=${direction}`),
  ]);
  player.traces = data.trace;
  player.bots = data.bots || [];
  player.obstacles = data.obstacles || [];
  player.botDt = 1 / ((race.config.physics && race.config.physics.control_hz) || 15);
  player.cars = race.cars
    .filter((c) => data.trace[c.car_name] && data.trace[c.car_name].t.length)
    .map((c, index) => {
      const trace = data.trace[c.car_name];
      return Object.assign({}, c, {
        index,
        result: c,
        trace,
        color: COLORS[index % COLORS.length],
        laps: Laps.laps(trace),
        incidents: Laps.incidents(trace),
      });
    });
  const ends = player.cars.map((c) => c.trace.t[c.trace.t.length - 1]);
  player.raceDuration = Math.max(0, ...ends, player.bots.length * player.botDt);
  player.marks = raceMarks(data.events || [], player.cars);
  player.view = new TrackView(document.getElementById("track-canvas"), geometry);
  document.getElementById("race-events").replaceChildren(...eventList(player.marks));
  document.getElementById("cars").replaceChildren(...player.cars.map(carPanel));
  document.getElementById("ghost-car").replaceChildren(
    ...player.cars.map((c) => Slip.el("option", { value: c.index }, carLabel(c))),
  );
  wireControls();
  setDuration(player.raceDuration);
  root.dataset.ready = "true";
}

// For tests and the curious: where each car is drawn now.
window.slipReplay = {
  positions: () => Object.fromEntries(player.cars.map((c) => [c.car_name, c.pose ? [c.pose.x, c.pose.y] : null])),
  marks: () => shownMarks().map((m) => ({ t: m.t, kind: m.kind, car: m.car, other: m.other, at_fault: m.at_fault, label: m.label })),
  state: () => ({ time: player.time, duration: player.duration, playing: player.playing, speed: player.speed }),
};

start().catch((err) => {
  root.dataset.error = String(err.message || err);
  root.prepend(Slip.el("p", { class: "error" }, "Could not load the replay: " + (err.message || err)));
});

// /garage/bench: re-score a stored race or training run with an edited reward (drawn as a
// heat line along the car's path beside the original reward), and compare runs' curves.
"use strict";

const Bench = {
  MAX_STEP_M: 1.0, // a longer jump between two steps is a respawn or a car parked after its race

  // A value's colour on the heat line: blue (lowest) through green to red (highest).
  color(value, low, high) {
    const t = high > low ? (value - low) / (high - low) : 0.5;
    return `hsl(${Math.round(240 * (1 - t))}, 85%, 48%)`;
  },

  // The body of POST /api/rescore from the form's fields.
  body(source, reward) {
    if (source.job) {
      const body = { reward_source: reward, training_job_id: Number(source.job) };
      if (source.episode !== "") body.episode = Number(source.episode);
      return body;
    }
    return { reward_source: reward, race_id: Number(source.race), car: source.car };
  },
};

const bench = { editor: null, geometry: {} };
const field = (id) => document.getElementById(id);

async function geometryOf(track, direction) {
  const key = `${track}/${direction || ""}`;
  if (!bench.geometry[key]) {
    const query = direction ? `?direction=${direction}` : "";
    const answer = await Slip.api(`/api/tracks/${encodeURIComponent(track)}${query}`);
    bench.geometry[key] = answer.ok ? answer.body : null;
  }
  return bench.geometry[key];
}

// The track and direction the chosen source ran on.
async function sourceTrack(source) {
  const answer = source.job
    ? await Slip.api(`/api/training-jobs/${Number(source.job)}`)
    : await Slip.api(`/api/races/${Number(source.race)}`);
  if (!answer.ok) return null;
  return source.job ? answer.body : answer.body.config;
}

function drawHeat(canvas, geometry, result, values, legend) {
  canvas.dataset.steps = "0";
  const view = new TrackView(canvas, geometry);
  view.drawTrack();
  if (!values) {
    field(legend).textContent = "(none: the run has no original reward)";
    return;
  }
  const low = Math.min(...values);
  const high = Math.max(...values);
  const ctx = view.ctx;
  ctx.lineWidth = 4;
  ctx.lineCap = "round";
  for (let i = 1; i < result.x.length; i++) {
    const jump = Math.hypot(result.x[i] - result.x[i - 1], result.y[i] - result.y[i - 1]);
    if (result.lap[i] !== result.lap[i - 1] || jump > Bench.MAX_STEP_M) continue; // a reset or a parked car
    const [ax, ay] = view.toScreen(result.x[i - 1], result.y[i - 1]);
    const [bx, by] = view.toScreen(result.x[i], result.y[i]);
    ctx.strokeStyle = Bench.color(values[i], low, high);
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
  }
  canvas.dataset.steps = String(values.length);
  field(legend).textContent = `(blue ${low.toFixed(2)} … red ${high.toFixed(2)} per step)`;
}

function source() {
  return {
    race: field("source-race").value,
    car: field("source-car").value.trim(),
    job: field("source-job").value,
    episode: field("source-episode").value,
  };
}

async function rescore() {
  const chosen = source();
  if (!chosen.job && !(chosen.race && chosen.car)) return Slip.say("rescore-result", "Choose a race and its car, or a training job.", "error");
  bench.editor.clearMarks();
  Slip.say("rescore-result", "Re-scoring in the sandbox…", "");
  const answer = await Slip.api("/api/rescore", {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(Bench.body(chosen, bench.editor.getValue())),
  });
  if (!answer.ok) {
    const text = Slip.errorText(answer);
    const line = Slip.lineOf(text);
    if (line) bench.editor.markLine(line, text);
    return Slip.say("rescore-result", text, "error");
  }
  const result = answer.body;
  const where = await sourceTrack(chosen);
  const geometry = where && (await geometryOf(where.track, where.direction));
  if (geometry) {
    drawHeat(field("heat-new"), geometry, result, result.reward, "legend-new");
    drawHeat(field("heat-original"), geometry, result, result.original, "legend-original");
  }
  field("rescore-laps").tBodies[0].replaceChildren(
    ...result.laps.map((lap) =>
      Slip.el(
        "tr",
        {},
        Slip.el("td", {}, lap.lap + 1),
        Slip.el("td", {}, lap.reward.toFixed(2)),
        Slip.el("td", {}, lap.original === null ? "—" : lap.original.toFixed(2)),
      ),
    ),
  );
  // said last, once the heat lines and the table are drawn
  const original = result.original_total === null ? "" : `, original ${result.original_total.toFixed(2)}`;
  Slip.say("rescore-result", `${result.steps} steps: total ${result.total.toFixed(2)}${original}.`, "ok");
}

// ---------------------------------------------------------------- compare runs
async function loadJobs() {
  const answer = await Slip.api("/api/training-jobs");
  if (!answer.ok) return;
  const wanted = new URLSearchParams(window.location.search).getAll("compare").map(Number);
  field("compare-jobs").replaceChildren(
    ...answer.body.map((job) =>
      Slip.el(
        "label",
        {},
        Slip.el("input", { type: "checkbox", value: job.id, checked: wanted.includes(job.id) }),
        ` ${job.name} (#${job.id}, ${job.status})`,
      ),
    ),
  );
  if (wanted.length) compare();
}

async function compare() {
  const chosen = Array.from(document.querySelectorAll("#compare-jobs input:checked"), (box) => ({
    id: Number(box.value),
    label: box.parentElement.textContent.trim(),
  }));
  const runs = await Promise.all(chosen.map((job) => Slip.api(`/api/training-jobs/${job.id}/metrics`)));
  const lines = (pick) =>
    chosen.map((job, n) => ({
      label: job.label,
      data: runs[n].ok ? runs[n].body.map((it) => [it.iteration, pick(it)]).filter(([, y]) => y !== null && y !== undefined) : [],
    }));
  RewardGraph.plot(field("compare-reward"), lines((it) => it.mean_reward));
  RewardGraph.plot(field("compare-completion"), lines((it) => (it.eval ? it.eval.progress : null)));
  RewardGraph.plot(field("compare-lap"), lines((it) => (it.eval ? it.eval.best_lap : null)));
}

// ---------------------------------------------------------------- start
function startBench() {
  const query = new URLSearchParams(window.location.search);
  field("source-race").value = query.get("race") || "";
  field("source-car").value = query.get("car") || "";
  field("source-job").value = query.get("job") || "";
  bench.editor = SlipEditor.create(field("bench-reward"));
  bench.editor.setValue("def reward_function(params):\n    return float(params['progress'])\n");
  field("rescore").addEventListener("click", rescore);
  field("compare").addEventListener("click", compare);
  if (!Slip.token()) Slip.say("bench-note", "Paste your API token (top right) to re-score and compare your runs.", "");
  else loadJobs();
}

document.addEventListener("slip-token", loadJobs);
startBench();

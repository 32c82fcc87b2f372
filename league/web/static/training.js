// /garage/jobs/{id}: one training job live (reward graph, a training race's top-down view,
// evaluations, log), then its model (or another of its checkpoints) evaluated on any track
// and submitted to an open event.
"use strict";

const Training = {
  SLOWER_EVALUATIONS: 3, // evaluations in a row slower than the best before the warning
  SLOWER_BY: 1.05, // "slower": over 5% above the best lap

  // The iterations as the reward graph's metrics ({columns, values}).
  metricsOf(iterations) {
    const values = { iteration: [], mean_reward: [], mean_progress: [], eval_progress: [] };
    for (const it of iterations) {
      values.iteration.push(it.iteration);
      values.mean_reward.push(it.mean_reward);
      values.mean_progress.push(it.mean_progress);
      values.eval_progress.push(it.eval ? it.eval.progress : null);
    }
    return { columns: Object.keys(values), values };
  },

  // The iteration whose evaluation is the model's (agents.evaluate.EvalSummary.score:
  // completion, then fewer off-tracks and crashes, then the earlier finish), or null.
  bestIteration(iterations) {
    const key = (e) => [e.progress, -(e.off_track + e.crashes), -(e.total_time ?? Infinity)];
    let best = null;
    for (const it of iterations) {
      if (!it.eval) continue;
      const k = key(it.eval);
      const b = best && key(best.eval);
      if (!best || k[0] > b[0] || (k[0] === b[0] && (k[1] > b[1] || (k[1] === b[1] && k[2] > b[2])))) best = it;
    }
    return best ? best.iteration : null;
  },

  // A plain-language warning when the evaluation laps have got slower for several
  // evaluations in a row while the average reward kept rising; null otherwise.
  lapWarning(iterations) {
    const laps = iterations.filter((it) => it.eval && it.eval.best_lap);
    const n = Training.SLOWER_EVALUATIONS;
    if (laps.length <= n) return null;
    const before = laps.slice(0, -n);
    const best = before.reduce((a, b) => (b.eval.best_lap < a.eval.best_lap ? b : a));
    const recent = laps.slice(-n);
    if (!recent.every((it) => it.eval.best_lap > best.eval.best_lap * Training.SLOWER_BY)) return null;
    const last = recent[recent.length - 1];
    if (!(last.mean_reward > best.mean_reward)) return null;
    return (
      `The evaluation laps have got slower for ${n} evaluations in a row (best ${best.eval.best_lap.toFixed(2)} s ` +
      `at iteration ${best.iteration}, now ${last.eval.best_lap.toFixed(2)} s) while the average reward kept ` +
      "rising: the reward function pays for something other than lap time. The run keeps the model of its " +
      "best evaluation; stop here, or change the reward and clone."
    );
  },
};

const page = {
  root: document.getElementById("training"),
  job: null,
  iterations: [],
  lastId: 0,
  view: null,
  poses: null,
  frame: 0,
  drawQueued: false,
};
page.jobId = Number(page.root.dataset.jobId);
const byId = (id) => document.getElementById(id);

function note(text, kind) {
  Slip.say("job-note", text, kind);
}

// The race type's own settings a job sets, e.g. " (bots 2, bot speed 1.2)".
function raceSettingsText(settings) {
  const given = Object.entries(settings).map(([option, value]) => `${option.replace(/_/g, " ")} ${value}`);
  return given.length ? ` (${given.join(", ")})` : "";
}

function renderJob(job) {
  page.job = job;
  byId("job-title").textContent = job.name;
  byId("job-description").textContent = job.description || "";
  byId("job-description").hidden = !job.description;
  const status = byId("status");
  status.textContent = job.status + (job.stop_requested && !Slip.TRAINING_ENDED.includes(job.status) ? " (stopping)" : "");
  status.dataset.status = job.status;
  status.className = "badge status-" + job.status;
  const facts = [
    `${job.track} (${job.direction || "file's direction"})`,
    job.race_type.replace(/_/g, " ") + raceSettingsText(job.race_settings),
    `${job.compute_minutes.toFixed(1)} of ${job.minutes} min`,
    job.best_lap_ms ? `best evaluation lap ${Slip.ms(job.best_lap_ms)}` : null,
    job.recipe ? `recipe ${job.recipe}` : null,
  ].filter(Boolean);
  byId("job-facts").textContent = facts.join(" · ");
  if (job.error) note(job.error, "error");
  byId("stop").hidden = Slip.TRAINING_ENDED.includes(job.status);
  byId("download").hidden = !job.has_run;
  if (job.model_id) showModelActions(job);
}

// ---------------------------------------------------------------- live graph and view
function redraw() {
  page.drawQueued = false;
  const best = Training.bestIteration(page.iterations);
  RewardGraph.draw(byId("reward-graph"), Training.metricsOf(page.iterations), { marker: best, markerLabel: "best model" });
  const warning = Training.lapWarning(page.iterations);
  byId("warning").hidden = !warning;
  byId("warning").textContent = warning || "";
}

function queueRedraw() {
  if (!page.drawQueued) {
    page.drawQueued = true;
    window.requestAnimationFrame(redraw);
  }
}

function addEvaluation(it) {
  const e = it.eval;
  byId("eval-laps").tBodies[0].append(
    Slip.el(
      "tr",
      {},
      Slip.el("td", {}, it.iteration),
      Slip.el("td", {}, `${e.progress.toFixed(0)}%`),
      Slip.el("td", {}, e.laps),
      Slip.el("td", {}, e.best_lap ? Slip.ms(e.best_lap * 1000) : "—"),
      Slip.el("td", {}, e.off_track),
    ),
  );
}

function animate() {
  if (!page.view || !page.poses) return;
  const { x, y, yaw } = page.poses;
  const i = page.frame % x.length;
  page.view.drawTrack();
  const trail = [];
  for (let k = Math.max(0, i - 40); k <= i; k++) trail.push([x[k], y[k]]);
  page.view.drawTrail(trail, "#ffb000");
  page.view.drawCar({ x: x[i], y: y[i], yaw: (yaw[i] * Math.PI) / 180 }, "#ffb000");
  page.frame += 1;
  window.setTimeout(() => window.requestAnimationFrame(animate), 66); // 15 control steps a second
}

function showPoses(poses) {
  if (!poses.x || !poses.x.length) return;
  const restart = !page.poses;
  page.poses = poses;
  page.frame = 0;
  byId("live-view").dataset.poses = String(poses.x.length);
  byId("live-note").textContent = `Iteration ${poses.iteration}: the longest race of its rollout (${poses.x.length} steps).`;
  if (restart) animate();
}

function onEvent(event) {
  page.lastId = event.id || page.lastId;
  if (event.event === "iteration") {
    page.iterations.push(event.data);
    if (event.data.eval) addEvaluation(event.data);
    queueRedraw();
  } else if (event.event === "poses") {
    showPoses(event.data);
  } else if (event.event === "log") {
    const log = byId("log");
    log.textContent = (log.textContent + event.data.line + "\n").split("\n").slice(-200).join("\n");
  } else if (event.event === "status") {
    renderJob(Object.assign({}, page.job, { status: event.data.status, error: event.data.error || page.job.error }));
  }
}

async function follow() {
  for (;;) {
    let status;
    try {
      status = await EventStream.follow(`/api/training-jobs/${page.jobId}/events`, page.lastId, onEvent);
    } catch (err) {
      status = 0; // the connection dropped: resume from the last event
    }
    const answer = await Slip.api(`/api/training-jobs/${page.jobId}`);
    if (answer.ok) renderJob(answer.body);
    if ((answer.ok && Slip.TRAINING_ENDED.includes(answer.body.status)) || status === 404) return;
    await new Promise((resolve) => window.setTimeout(resolve, 1000));
  }
}

// ---------------------------------------------------------------- choose, evaluate and submit
function showModel(id, what) {
  page.modelId = id;
  byId("model-link").replaceChildren(
    "Evaluating and submitting ",
    Slip.el("a", { href: `/models/${id}` }, `model ${id}`),
    ` (${what}).`,
  );
}

async function loadCheckpoints() {
  const answer = await Slip.api(`/api/training-jobs/${page.jobId}/checkpoints`);
  const form = byId("checkpoint-form");
  form.hidden = !answer.ok || !answer.body.length;
  if (!answer.ok) Slip.say("checkpoint-result", "The run's checkpoints cannot be listed: " + Slip.errorText(answer), "error");
  if (form.hidden) return;
  // Checkpoints of one iteration share one model: the first of them is the one shown chosen.
  const current = answer.body.findIndex((c) => c.model_id === page.modelId);
  const rows = answer.body.map((c, i) => {
    const id = `checkpoint-${c.name}`;
    const choice = Slip.el("input", { type: "radio", name: "checkpoint", id, value: c.name, checked: i === current });
    return Slip.el(
      "tr",
      { "data-checkpoint": c.name },
      Slip.el("td", {}, choice, " ", Slip.el("label", { for: id }, c.by)),
      Slip.el("td", {}, c.iteration),
      Slip.el("td", {}, `${c.minutes.toFixed(1)} min`),
      Slip.el("td", {}, c.completion === null ? "—" : `${c.completion.toFixed(0)}%`),
      Slip.el("td", {}, c.best_lap ? Slip.ms(c.best_lap * 1000) : "—"),
      Slip.el("td", {}, c.model_id ? Slip.el("a", { href: `/models/${c.model_id}` }, `model ${c.model_id}`) : "not yet"),
    );
  });
  byId("checkpoints").tBodies[0].replaceChildren(...rows);
}

byId("checkpoint-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const chosen = byId("checkpoint-form").querySelector("input[name=checkpoint]:checked");
  if (!chosen) return Slip.say("checkpoint-result", "Choose a checkpoint first.", "error");
  Slip.say("checkpoint-result", "Validating the checkpoint's model…", "");
  const answer = await Slip.api(`/api/training-jobs/${page.jobId}/checkpoints/${chosen.value}/model`, { method: "POST" });
  if (!answer.ok) return Slip.say("checkpoint-result", Slip.errorText(answer), "error");
  const what = chosen.labels[0].textContent;
  showModel(answer.body.id, `the checkpoint of the ${what}`);
  Slip.say("checkpoint-result", `Model ${answer.body.id} holds the checkpoint of the ${what}.`, "ok");
  loadCheckpoints();
  loadEvaluations();
});

async function showModelActions(job) {
  const section = byId("model-actions");
  if (!section.hidden) return;
  section.hidden = false;
  showModel(job.model_id, "the job's model: its best evaluation's weights");
  loadCheckpoints();
  const [catalogue, events] = await Promise.all([Slip.getPatiently("/api/garage/catalogue"), Slip.getPatiently("/api/events")]);
  if (catalogue.ok) {
    byId("evaluate-track").replaceChildren(
      ...catalogue.body.tracks.map((t) => Slip.el("option", { value: t.name, selected: t.name === job.track }, t.display_name)),
    );
  } else {
    Slip.say("evaluate-result", `The track list did not load: ${Slip.errorText(catalogue)} Reload the page to try again.`, "error");
  }
  if (!events.ok) Slip.say("submit-result", `The open events did not load: ${Slip.errorText(events)} Reload the page to try again.`, "error");
  const open = events.ok ? events.body.filter((e) => e.status === "open" && e.race_type === job.race_type) : [];
  byId("submit-event").replaceChildren(
    ...(open.length
      ? open.map((e) => Slip.el("option", { value: e.id }, `${e.name} (${e.track})`))
      : [Slip.el("option", { value: "" }, events.ok ? `no open ${job.race_type.replace(/_/g, " ")} event` : "events not loaded")]),
  );
  byId("submit").disabled = !open.length;
  loadEvaluations();
}

async function loadEvaluations() {
  const answer = await Slip.api(`/api/models/${page.modelId}/evaluations`);
  if (!answer.ok) return;
  const rows = answer.body.flatMap((ev) => {
    const races = ev.races.length ? ev.races : [null];
    return races.map((r) =>
      Slip.el(
        "tr",
        {},
        Slip.el("td", {}, `${ev.track} (${ev.direction})`),
        Slip.el("td", {}, r ? r.status : ev.status),
        Slip.el("td", {}, r ? r.laps : "—"),
        Slip.el("td", {}, r ? Slip.ms(r.best_lap_ms) : "—"),
        Slip.el("td", {}, r ? Slip.ms(r.total_ms) : "—"),
        Slip.el("td", {}, r ? r.off_track : "—"),
        Slip.el("td", {}, r ? Slip.el("a", { href: `/races/${r.race_id}` }, "replay") : ev.error || "waiting for a worker"),
      ),
    );
  });
  byId("evaluations").tBodies[0].replaceChildren(...rows);
  if (answer.body.some((ev) => ev.status === "queued" || ev.status === "running")) window.setTimeout(loadEvaluations, 2000);
}

byId("evaluate-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  // The job's race type with its own settings (boxes, bots); a head-to-model job alone.
  const sameType = page.job.race_type !== "head_to_model";
  const body = {
    track: byId("evaluate-track").value,
    direction: byId("evaluate-direction").value,
    race_type: sameType ? page.job.race_type : "time_trial",
    race_settings: sameType ? page.job.race_settings : {},
    laps: Number(byId("evaluate-laps").value),
  };
  Slip.say("evaluate-result", "Queuing the evaluation…", "");
  const answer = await Slip.api(`/api/models/${page.modelId}/evaluations`, {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(body),
  });
  if (!answer.ok) return Slip.say("evaluate-result", Slip.errorText(answer), "error");
  Slip.say("evaluate-result", "Queued: a league worker races it; the result and its replay appear below.", "ok");
  loadEvaluations();
});

byId("submit-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const eventId = byId("submit-event").value;
  if (!eventId) return;
  const answer = await Slip.api(`/api/events/${eventId}/entries`, {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ model_id: page.modelId }),
  });
  if (!answer.ok) return Slip.say("submit-result", Slip.errorText(answer), "error");
  Slip.say("submit-result", "Entered. ", "ok", Slip.el("a", { href: `/events/${eventId}` }, "See the leaderboard"));
});

// ---------------------------------------------------------------- stop and download
byId("stop").addEventListener("click", async () => {
  const answer = await Slip.api(`/api/training-jobs/${page.jobId}/stop`, { method: "POST" });
  if (answer.ok) {
    renderJob(answer.body);
    note("Stopping: the trainer keeps what it has trained so far.", "ok");
  } else note(answer.body?.detail || "Could not stop the job.", "error");
});

byId("download").addEventListener("click", async () => {
  const response = await fetch(`/api/training-jobs/${page.jobId}/run.zip`, {
    headers: { Authorization: "Bearer " + Slip.token() },
  });
  if (!response.ok) return note(`The run folder could not be downloaded (HTTP ${response.status}).`, "error");
  const link = Slip.el("a", { href: URL.createObjectURL(await response.blob()), download: `training-job-${page.jobId}.zip` });
  link.click();
  URL.revokeObjectURL(link.href);
});

// ---------------------------------------------------------------- start
async function start() {
  if (page.started) return;
  if (!Slip.token()) return note("Paste your API token (top right) to watch your training jobs.", "");
  const answer = await Slip.api(`/api/training-jobs/${page.jobId}`);
  if (!answer.ok) return note(answer.body?.detail || `This job cannot be shown (HTTP ${answer.status}).`, "error");
  page.started = true;
  note("", "");
  renderJob(answer.body);
  const direction = answer.body.direction ? `?direction=${answer.body.direction}` : "";
  const geometry = await Slip.api(`/api/tracks/${encodeURIComponent(answer.body.track)}${direction}`);
  if (geometry.ok) {
    page.view = new TrackView(byId("live-view"), geometry.body);
    page.view.drawTrack();
  }
  follow();
}

document.addEventListener("slip-token", start);
start();

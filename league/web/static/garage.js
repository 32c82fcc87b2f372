// /garage: the signed-in racer's training jobs and models, with create, clone, stop and
// delete (GET /api/training-jobs, GET /api/models, the track thumbnails of the catalogue).
"use strict";

function note(text, kind) {
  Slip.say("garage-note", text, kind);
}

function actionButton(label, onClick, attrs) {
  const button = Slip.el("button", Object.assign({ type: "button", class: "link" }, attrs), label);
  button.addEventListener("click", onClick);
  return button;
}

async function stopJob(job) {
  const answer = await Slip.api(`/api/training-jobs/${job.id}/stop`, { method: "POST" });
  if (!answer.ok) note(answer.body?.detail || `Stopping failed (HTTP ${answer.status}).`, "error");
  refresh();
}

async function deleteJob(job) {
  if (!window.confirm(`Delete training job "${job.name}" and its stored run? Its models stay.`)) return;
  const answer = await Slip.api(`/api/training-jobs/${job.id}`, { method: "DELETE" });
  if (!answer.ok) note(answer.body?.detail || `Deleting failed (HTTP ${answer.status}).`, "error");
  else note(`Deleted training job "${job.name}".`, "ok");
  refresh();
}

function jobRow(job, thumbnails) {
  const ended = Slip.TRAINING_ENDED.includes(job.status);
  const thumb = thumbnails[job.options.track];
  const status = Slip.el("td", {}, Slip.el("span", { class: `badge status-${job.status}` }, job.status));
  if (job.error) status.append(Slip.el("div", { class: "error small" }, job.error));
  return Slip.el(
    "tr",
    { "data-job-id": job.id },
    Slip.el("td", {}, thumb ? Slip.el("img", { src: thumb, alt: job.options.track, width: 72, height: 48, class: "thumb-img" }) : job.options.track || "—"),
    Slip.el(
      "td",
      {},
      Slip.el("a", { href: `/garage/jobs/${job.id}` }, job.name),
      job.description ? Slip.el("small", { class: "muted job-description" }, job.description) : null,
    ),
    status,
    Slip.el("td", {}, Slip.ms(job.best_lap_ms)),
    Slip.el("td", {}, `${job.compute_minutes.toFixed(1)} / ${job.minutes}`),
    Slip.el("td", { class: "muted" }, Slip.date(job.created_at)),
    Slip.el(
      "td",
      { class: "row-actions" },
      job.model_id ? Slip.el("a", { href: `/models/${job.model_id}`, class: "model-link" }, "model") : null,
      job.has_run ? Slip.el("a", { href: `/garage/new?clone=${job.id}`, class: "clone-link" }, "clone") : null,
      ended ? null : actionButton("stop", () => stopJob(job), { disabled: job.stop_requested }),
      ended ? actionButton("delete", () => deleteJob(job), { class: "link danger" }) : null,
    ),
  );
}

function modelRow(model) {
  return Slip.el(
    "tr",
    { "data-model-id": model.id },
    Slip.el("td", {}, Slip.el("a", { href: `/models/${model.id}` }, model.name)),
    Slip.el("td", {}, model.action_space_type),
    Slip.el("td", {}, (model.sensors || []).join(", ")),
    Slip.el("td", { class: "muted" }, Slip.date(model.created_at)),
  );
}

async function thumbnailsByTrack() {
  const answer = await Slip.api("/api/garage/catalogue");
  return answer.ok ? Object.fromEntries(answer.body.tracks.map((t) => [t.name, t.thumbnail_url])) : {};
}

function fill(id, rows, empty, columns) {
  const body = document.querySelector(`#${id} tbody`);
  body.replaceChildren(...(rows.length ? rows : [Slip.el("tr", {}, Slip.el("td", { colspan: columns, class: "muted" }, empty))]));
}

async function refresh() {
  const garage = document.querySelector("main");
  if (!Slip.token()) {
    fill("jobs", [], "", 7);
    fill("models", [], "", 4);
    note("You are not signed in: paste your API token (top right) to see your garage.", "error");
    garage.dataset.loaded = "true";
    return;
  }
  const [jobs, models, thumbnails] = await Promise.all([Slip.api("/api/training-jobs"), Slip.api("/api/models"), thumbnailsByTrack()]);
  if (!jobs.ok || !models.ok) {
    note((jobs.body || models.body)?.detail || "Your garage could not be loaded.", "error");
    return;
  }
  if (document.getElementById("garage-note").classList.contains("error")) note("");
  fill("jobs", jobs.body.map((j) => jobRow(j, thumbnails)), "No training jobs yet: create a model.", 7);
  fill("models", models.body.map(modelRow), "No models yet.", 4);
  garage.dataset.loaded = "true";
}

note("");
document.addEventListener("slip-token", refresh);
refresh();

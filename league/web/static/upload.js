// Upload page: send a model archive with the stored token; show the validator's verdict.
"use strict";

function showProblems(body, status) {
  const box = document.getElementById("upload-result");
  const detail = (body && body.detail) || `The upload failed (HTTP ${status}).`;
  const problems = (body && body.problems) || [];
  box.className = "result error";
  box.replaceChildren(
    Slip.el("p", {}, detail),
    problems.length ? Slip.el("ul", { class: "problems" }, ...problems.map((p) => Slip.el("li", {}, p.message))) : null,
  );
}

function showModel(model, status) {
  const box = document.getElementById("upload-result");
  box.className = "result ok";
  box.replaceChildren(
    Slip.el(
      "p",
      {},
      status === 201 ? "Uploaded and validated: " : "You uploaded this file before: ",
      Slip.el("a", { href: `/models/${model.id}` }, `${model.name} (model ${model.id})`),
    ),
  );
}

async function upload(event) {
  event.preventDefault();
  const box = document.getElementById("upload-result");
  if (!Slip.token()) {
    box.className = "result error";
    box.textContent = "Paste your API token (top right) first.";
    return;
  }
  const file = document.getElementById("upload-file").files[0];
  if (!file) return;
  const form = new FormData();
  form.append("file", file, file.name);
  const name = document.getElementById("upload-name").value.trim();
  if (name) form.append("name", name);
  box.className = "result";
  box.textContent = "Uploading and validating…";
  const answer = await Slip.api("/api/models", { method: "POST", body: form });
  if (answer.ok) {
    showModel(answer.body, answer.status);
    listModels();
  } else {
    showProblems(answer.body, answer.status);
  }
}

async function listModels() {
  const table = document.getElementById("my-models");
  const note = document.getElementById("my-models-note");
  if (!Slip.token()) {
    table.tBodies[0].replaceChildren();
    note.textContent = "Paste your API token (top right) to see your models.";
    return;
  }
  const answer = await Slip.api("/api/models");
  if (!answer.ok) {
    note.textContent = answer.body?.detail || "Your models could not be listed.";
    return;
  }
  note.textContent = answer.body.length ? "" : "No models yet.";
  table.tBodies[0].replaceChildren(
    ...answer.body.map((m) =>
      Slip.el(
        "tr",
        {},
        Slip.el("td", {}, Slip.el("a", { href: `/models/${m.id}` }, m.name)),
        Slip.el("td", {}, m.action_space_type),
        Slip.el("td", {}, m.sensors.join(", ")),
        Slip.el("td", { class: "muted" }, Slip.date(m.created_at)),
      ),
    ),
  );
}

document.getElementById("upload-form").addEventListener("submit", upload);
document.addEventListener("slip-token", listModels);
listModels();

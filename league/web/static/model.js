// Model page: the validation report, results history and training reward graph.
// Private parts need the owner's token (stored in this browser by the header form).
"use strict";

const modelRoot = document.getElementById("model");
const modelId = modelRoot.dataset.modelId;

function reportRows(model) {
  const info = model.info || {};
  const space = info.action_space || {};
  const rows = [
    ["Validation", info.archive_sha256 ? "passed (checked by the validator on upload)" : "public view"],
    ["Owner", model.owner],
    ["Uploaded", Slip.date(model.created_at)],
    ["Action space", model.action_space_type + (space.actions ? ` (${space.actions.length} actions)` : "")],
    ["Sensors", model.sensors.join(", ") || "—"],
  ];
  if (info.archive_sha256) {
    rows.push(
      ["Archive", `${info.archive_bytes} bytes, sha256 ${info.archive_sha256.slice(0, 16)}…`],
      ["Inputs", (info.observation || []).map((i) => `${i.name} ${JSON.stringify(i.shape)} ${i.dtype}`).join(", ")],
      ["Output", info.output ? `${info.output.convention}, size ${info.output.size}` : "—"],
      ["Network", [info.neural_network, info.network_preset].filter(Boolean).join(" / ")],
      ["Training", info.training_algorithm],
      ["Inference latency", info.latency_ms === null || info.latency_ms === undefined ? "—" : `${info.latency_ms.toFixed(2)} ms`],
      ["Reward function", info.has_reward_function ? "included" : "not included"],
      ["Training metrics", info.has_metrics ? "included" : "not included"],
    );
    for (const [key, value] of Object.entries(info.training_summary || {})) rows.push([`  ${key}`, String(value)]);
  }
  return rows;
}

function renderReport(model) {
  document.getElementById("model-title").textContent = `${model.name} (model ${model.id})`;
  const list = document.getElementById("report");
  list.replaceChildren(...reportRows(model).flatMap(([k, v]) => [Slip.el("dt", {}, k), Slip.el("dd", {}, v)]));
}

function renderSuspensions(model) {
  const shown = model.suspensions || [];
  const section = document.getElementById("suspensions");
  section.hidden = !shown.length;
  const items = shown.map((s) =>
    Slip.el(
      "li",
      {},
      Slip.el("a", { href: `/events/${s.event_id}` }, s.event_name),
      ` (${Slip.date(s.suspended_at)}): ${s.message}`,
    ),
  );
  section.replaceChildren(...(shown.length ? [Slip.el("h2", {}, "Suspended from events"), Slip.el("ul", {}, ...items)] : []));
}

function renderHistory(races) {
  const table = document.getElementById("history");
  const head = Slip.el("tr", {}, ...["Race", "Event", "Status", "Pos", "Laps", "Best lap", "Total", "Off-track", "Crashes", "When"].map((h) => Slip.el("th", {}, h)));
  const rows = races.map((r) =>
    Slip.el(
      "tr",
      {},
      Slip.el("td", {}, Slip.el("a", { href: `/races/${r.race_id}` }, `race ${r.race_id}`)),
      Slip.el("td", {}, Slip.el("a", { href: `/events/${r.event_id}` }, r.event_name)),
      Slip.el("td", {}, r.status),
      Slip.el("td", {}, r.finish_position),
      Slip.el("td", {}, r.laps),
      Slip.el("td", {}, Slip.ms(r.best_ms)),
      Slip.el("td", {}, Slip.ms(r.total_ms)),
      Slip.el("td", {}, r.off_track_count),
      Slip.el("td", {}, r.crash_count),
      Slip.el("td", { class: "muted" }, Slip.date(r.created_at)),
    ),
  );
  table.replaceChildren(Slip.el("thead", {}, head), Slip.el("tbody", {}, ...rows));
  document.getElementById("history-note").textContent = races.length ? "" : "No races yet.";
}

// ---------------------------------------------------------------- loading
async function loadModel() {
  const note = document.getElementById("model-note");
  const answer = await Slip.api(`/api/models/${modelId}`);
  if (!answer.ok) {
    note.textContent = Slip.token()
      ? answer.body?.detail || "This model cannot be shown."
      : "This model is private or not found: paste your API token (top right) to see your own models.";
    return;
  }
  const model = answer.body;
  renderReport(model);
  if (model.visibility !== "owner") {
    note.textContent = "Public view: the owner sees the full report, results and reward graph with their token.";
    return;
  }
  note.textContent = "";
  renderSuspensions(model);
  const [races, metrics] = await Promise.all([
    Slip.api(`/api/models/${modelId}/races`),
    Slip.api(`/api/models/${modelId}/metrics`),
  ]);
  if (races.ok) renderHistory(races.body);
  const drawn = metrics.ok && RewardGraph.draw(document.getElementById("reward-graph"), metrics.body);
  document.getElementById("metrics-note").textContent = drawn ? "" : "This model was uploaded without training metrics.";
}

document.addEventListener("slip-token", loadModel);
loadModel();

// Event page: the leaderboard and latest races, polled so new results appear by themselves.
"use strict";

const POLL_MS = 4000;
const board = document.getElementById("leaderboard");
const eventId = board.dataset.eventId;
const headToHead = board.dataset.raceType === "head_to_model";
let lastBoard = "";
let lastRaces = "";

const TIME_COLUMNS = [
  ["Rank", (r) => r.rank],
  ["Racer", (r) => r.alias],
  ["Model", (r) => r.model_name],
  ["Time", (r) => Slip.ms(r.ranking_score_ms), "score"],
  ["Best lap", (r) => Slip.ms(r.best_lap_ms)],
  ["Avg lap", (r) => Slip.ms(r.average_lap_ms)],
  ["Total", (r) => Slip.ms(r.total_time_ms)],
  ["Laps", (r) => r.lap_count],
  ["Off-track", (r) => r.off_track_count],
  ["Collisions", (r) => r.collision_count],
  ["At fault", (r) => r.at_fault_collisions],
  ["Resets", (r) => r.reset_count],
  ["Submissions", (r) => r.submission_count],
];

const RATING_COLUMNS = [
  ["Rank", (r) => r.rank],
  ["Racer", (r) => r.alias],
  ["Model", (r) => r.model_name],
  ["μ", (r) => fixed(r.mu)],
  ["σ", (r) => fixed(r.sigma)],
  ["μ − 3σ", (r) => fixed(r.ordinal), "score"],
  ["Uncertainty", null, "bar"],
  ["Laps", (r) => r.lap_count],
  ["Best lap", (r) => Slip.ms(r.best_lap_ms)],
  ["Off-track", (r) => r.off_track_count],
  ["Collisions", (r) => r.collision_count],
  ["Overtakes", (r) => r.overtakes],
  ["At fault", (r) => r.at_fault_collisions],
  ["Laps led", (r) => r.laps_led],
  ["Submissions", (r) => r.submission_count],
];

function fixed(value) {
  return value === null || value === undefined ? "—" : value.toFixed(2);
}

// The rating interval [mu - 3 sigma, mu + 3 sigma] on a scale shared by all rows.
function uncertaintyBar(row, scale) {
  if (row.mu === null || row.sigma === null) return "—";
  const span = scale.hi - scale.lo || 1;
  const pos = (v) => (100 * (v - scale.lo)) / span;
  const left = pos(row.mu - 3 * row.sigma);
  const right = pos(row.mu + 3 * row.sigma);
  return Slip.el(
    "div",
    { class: "ubar", title: `μ ${fixed(row.mu)} ± 3σ (${fixed(3 * row.sigma)})` },
    Slip.el("span", { class: "range", style: `left:${left}%;width:${right - left}%` }),
    Slip.el("span", { class: "mu", style: `left:${pos(row.mu)}%` }),
  );
}

function ratingScale(rows) {
  const rated = rows.filter((r) => r.mu !== null && r.sigma !== null);
  if (!rated.length) return { lo: 0, hi: 1 };
  return {
    lo: Math.min(...rated.map((r) => r.mu - 3 * r.sigma)),
    hi: Math.max(...rated.map((r) => r.mu + 3 * r.sigma)),
  };
}

function renderBoard(data) {
  const columns = headToHead ? RATING_COLUMNS : TIME_COLUMNS;
  const head = Slip.el("tr", {}, ...columns.map(([title]) => Slip.el("th", {}, title)));
  head.append(Slip.el("th", {}, "Replay"));
  board.tHead.replaceChildren(head);
  const scale = ratingScale(data.rows);
  const rows = data.rows.map((row) => {
    const cells = columns.map(([, value, kind]) =>
      Slip.el("td", { class: kind || null }, kind === "bar" ? uncertaintyBar(row, scale) : value(row)),
    );
    const link = row.race_id ? Slip.el("a", { href: `/races/${row.race_id}` }, "watch") : "—";
    cells.push(Slip.el("td", {}, link));
    return Slip.el("tr", { "data-model-id": row.model_id, "data-rank": row.rank }, ...cells);
  });
  if (!rows.length) {
    rows.push(Slip.el("tr", {}, Slip.el("td", { colspan: columns.length + 1, class: "muted" }, "No results yet.")));
  }
  board.tBodies[0].replaceChildren(...rows);
  board.dataset.loaded = "true";
}

function renderRaces(races) {
  const table = document.getElementById("races");
  const rows = races.map((race) => {
    const cars = race.cars
      .map((c) => `${c.finish_position}. ${c.alias || c.car_name} (${c.status}, ${Slip.ms(c.total_ms ?? c.best_ms)})`)
      .join("  ");
    return Slip.el(
      "tr",
      {},
      Slip.el("td", {}, Slip.el("a", { href: `/races/${race.id}` }, `race ${race.id}`)),
      Slip.el("td", { class: "muted" }, Slip.date(race.created_at)),
      Slip.el("td", {}, cars),
    );
  });
  if (!rows.length) rows.push(Slip.el("tr", {}, Slip.el("td", { class: "muted" }, "No races yet.")));
  table.tBodies[0].replaceChildren(...rows);
}

async function refresh() {
  const [boardAnswer, racesAnswer] = await Promise.all([
    Slip.api(`/api/events/${eventId}/leaderboard`),
    Slip.api(`/api/races?event=${eventId}&limit=20`),
  ]);
  if (boardAnswer.ok) {
    const text = JSON.stringify(boardAnswer.body);
    if (text !== lastBoard) {
      lastBoard = text;
      renderBoard(boardAnswer.body);
    }
  }
  if (racesAnswer.ok) {
    const text = JSON.stringify(racesAnswer.body);
    if (text !== lastRaces) {
      lastRaces = text;
      renderRaces(racesAnswer.body);
    }
  }
  document.getElementById("updated").textContent =
    "Updated " + new Date().toLocaleTimeString() + " (refreshes by itself).";
}

async function poll() {
  try {
    await refresh();
  } finally {
    window.setTimeout(poll, POLL_MS);
  }
}

poll();

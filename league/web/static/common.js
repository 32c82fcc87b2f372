// Shared helpers for every page: the stored API token, JSON fetches, DOM building, formats.
"use strict";

const TOKEN_KEY = "slipstream.token";

const Slip = {
  token() {
    return window.localStorage.getItem(TOKEN_KEY) || "";
  },

  // GET or send JSON / form data to the API; the stored token goes in a bearer header.
  async api(path, options = {}) {
    const headers = Object.assign({}, options.headers || {});
    const token = Slip.token();
    if (token) headers["Authorization"] = "Bearer " + token;
    const response = await fetch(path, Object.assign({}, options, { headers }));
    let body = null;
    try {
      body = await response.json();
    } catch (err) {
      body = null;
    }
    return { ok: response.ok, status: response.status, body };
  },

  // GET `path`, trying again after a network error, a 429 or a 5xx (1, 2, 4 s apart); the
  // last answer, or { ok: false, status: 0 } when the server never answered.
  async getPatiently(path, tries = 4) {
    let answer = { ok: false, status: 0, body: null };
    for (let attempt = 0; attempt < tries; attempt++) {
      if (attempt) await new Promise((resolve) => window.setTimeout(resolve, 1000 * 2 ** (attempt - 1)));
      try {
        answer = await Slip.api(path);
      } catch (err) {
        answer = { ok: false, status: 0, body: null };
        continue;
      }
      if (answer.ok || (answer.status !== 429 && answer.status < 500)) return answer;
    }
    return answer;
  },

  // Build an element: el("td", {class: "x"}, "text", child, ...); text is never parsed as HTML.
  el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [key, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (key === "class") node.className = value;
      else if (key === "style") node.style.cssText = value;
      else node.setAttribute(key, value === true ? "" : value);
    }
    for (const child of children) {
      if (child === null || child === undefined) continue;
      node.append(child instanceof Node ? child : String(child));
    }
    return node;
  },

  // Milliseconds as m:ss.mmm (DeepRacer's lap-time format); "—" when missing.
  ms(value) {
    if (value === null || value === undefined) return "—";
    const total = Math.round(value);
    const minutes = Math.floor(total / 60000);
    const seconds = ((total % 60000) / 1000).toFixed(3).padStart(6, "0");
    return minutes + ":" + seconds;
  },

  duration(seconds) {
    const s = Math.max(0, Math.floor(seconds));
    const d = Math.floor(s / 86400);
    const h = Math.floor((s % 86400) / 3600);
    const m = Math.floor((s % 3600) / 60);
    if (d > 0) return d + "d " + h + "h";
    if (h > 0) return h + "h " + m + "m";
    return m + "m " + String(s % 60).padStart(2, "0") + "s";
  },

  // Show `text` (and `children`) in the status box `id`, styled by `kind` ("ok", "error" or
  // ""); an empty message hides the box.
  say(id, text, kind, ...children) {
    const box = document.getElementById(id);
    box.className = "result" + (kind ? " " + kind : "");
    box.replaceChildren(text, ...children);
    box.hidden = !text && !children.length;
  },

  // An API error's text: FastAPI's detail string, or its validation list.
  errorText(answer) {
    const detail = answer.body && answer.body.detail;
    if (Array.isArray(detail)) return detail.map((d) => `${(d.loc || []).slice(1).join(".")}: ${d.msg}`).join("; ");
    if (detail) return detail;
    return answer.status ? `The request failed (HTTP ${answer.status}).` : "The server did not answer.";
  },

  // The line an error message names ("... at line 3"), or null.
  lineOf(message) {
    const match = /\bline (\d+)/.exec(message || "");
    return match ? Number(match[1]) : null;
  },

  TRAINING_ENDED: ["done", "stopped", "failed"], // a training job's statuses once it has ended

  date(iso) {
    return iso ? new Date(iso).toISOString().slice(0, 16).replace("T", " ") + " UTC" : "—";
  },
};

// Countdowns: <span class="countdown" data-closes-at="ISO time"> ticks down once a second.
// The page holds the absolute closing time, so a cached copy (304) still counts right.
function startCountdowns() {
  const nodes = Array.from(document.querySelectorAll(".countdown"));
  const tick = () => {
    for (const node of nodes) {
      const left = (Date.parse(node.dataset.closesAt) - Date.now()) / 1000;
      node.textContent = Slip.duration(Math.max(left, 0));
    }
  };
  tick();
  if (nodes.length) window.setInterval(tick, 1000);
}

// The token form in the header: save to / forget from localStorage, show who is signed in.
async function showSignedIn() {
  const who = document.getElementById("token-who");
  const forget = document.getElementById("token-forget");
  const input = document.getElementById("token-input");
  const save = document.getElementById("token-save");
  if (!Slip.token()) {
    who.textContent = "not signed in";
    forget.hidden = true;
    input.hidden = save.hidden = false;
    return;
  }
  const me = await Slip.api("/api/racers/me");
  who.textContent = me.ok ? "signed in as " + me.body.alias : "token not accepted";
  forget.hidden = false;
  input.hidden = save.hidden = me.ok;
}

function setUpTokenForm() {
  const form = document.getElementById("token-form");
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    const input = document.getElementById("token-input");
    const value = input.value.trim();
    if (value) window.localStorage.setItem(TOKEN_KEY, value);
    input.value = "";
    showSignedIn().then(() => document.dispatchEvent(new Event("slip-token")));
  });
  document.getElementById("token-forget").addEventListener("click", () => {
    window.localStorage.removeItem(TOKEN_KEY);
    showSignedIn().then(() => document.dispatchEvent(new Event("slip-token")));
  });
  showSignedIn();
}

setUpTokenForm();
startCountdowns();

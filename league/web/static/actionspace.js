// The action-space builder of /garage/new: DeepRacer's discrete builder (max steering,
// steering granularity, max speed, speed granularity -> an editable table of actions) or a
// continuous range, drawn as the console's polar graph (steering angle = angle, speed =
// radius), whose dots and sector edges can be dragged, producing the spec string a training job takes (agents/action_spaces.py):
// console:MAX_STEER:STEER_GRAN:MAX_SPEED:SPEED_GRAN, list:STEER/SPEED,... or
// continuous:STEER_LOW:STEER_HIGH:SPEED_LOW:SPEED_HIGH. The maths are pure functions.
"use strict";

const SlipActions = {
  // The catalogue's action_space facts, under one set of names.
  limits(raw) {
    const pick = (...keys) => keys.map((k) => raw[k]).find((v) => v !== undefined);
    return {
      maxSteer: pick("max_steering_deg", "steering_max", "max_steering"),
      minSpeed: pick("min_speed", "speed_min"),
      maxSpeed: pick("max_speed", "speed_max"),
      steerGrans: pick("steering_granularities", "steering_granularity"),
      speedGrans: pick("speed_granularities", "speed_granularity"),
      maxActions: pick("max_discrete_actions", "max_actions"),
      // The console's default space ("default"): 30 deg in 5 steps, 0.8 m/s in 2.
      consoleDefault: raw.console_default || { max_steering_deg: 30, steering_granularity: 5, max_speed: 0.8, speed_granularity: 2 },
    };
  },

  // Two decimals, as the console shows and stores action values.
  round2: (x) => Math.round(x * 100) / 100,

  // The console's discrete space: steering evenly -max..+max, speed max/g..max; every
  // combination, steering then speed (the console's numbering).
  consoleActions(maxSteer, steerGran, maxSpeed, speedGran) {
    const half = (steerGran - 1) / 2;
    const actions = [];
    for (let k = -half; k <= half; k++) {
      for (let j = 1; j <= speedGran; j++) {
        actions.push({ steer: SlipActions.round2((maxSteer * k) / half), speed: SlipActions.round2((maxSpeed * j) / speedGran) });
      }
    }
    return actions;
  },

  sameActions(a, b) {
    return a.length === b.length && a.every((x, i) => x.steer === b[i].steer && x.speed === b[i].speed);
  },

  // The job's spec string for a builder state.
  specOf(state) {
    if (state.type === "continuous") {
      const c = state.continuous;
      return `continuous:${c.steerLow}:${c.steerHigh}:${c.speedLow}:${c.speedHigh}`;
    }
    const b = state.console;
    if (SlipActions.sameActions(state.actions, SlipActions.consoleActions(b.maxSteer, b.steerGran, b.maxSpeed, b.speedGran))) {
      return `console:${b.maxSteer}:${b.steerGran}:${b.maxSpeed}:${b.speedGran}`;
    }
    return "list:" + state.actions.map((a) => `${a.steer}/${a.speed}`).join(",");
  },

  // A builder state from a spec string (null for forms the builder does not edit, such as
  // a file name); `base` gives the fields the spec does not set.
  stateOf(spec, base) {
    const text = String(spec || "").trim();
    const [keyword, ...rest] = text.split(":");
    const nums = rest.map(Number);
    const state = JSON.parse(JSON.stringify(base));
    const consoleState = (maxSteer, steerGran, maxSpeed, speedGran) => {
      state.type = "discrete";
      state.console = { maxSteer, steerGran, maxSpeed, speedGran };
      state.actions = SlipActions.consoleActions(maxSteer, steerGran, maxSpeed, speedGran);
      return state;
    };
    const short = /^(\d+)x(\d+)@([^/]+)(?:\/(.+))?$/i.exec(text);
    if (keyword.toLowerCase() === "default") {
      const b = base.console;
      return consoleState(b.maxSteer, b.steerGran, b.maxSpeed, b.speedGran);
    }
    if (keyword.toLowerCase() === "console" && nums.length === 4 && nums.every(Number.isFinite)) {
      return consoleState(...nums);
    }
    if (short) return consoleState(short[4] === undefined ? base.console.maxSteer : Number(short[4]), Number(short[1]), Number(short[3]), Number(short[2]));
    if (keyword.toLowerCase() === "continuous" && nums.length === 4 && nums.every(Number.isFinite)) {
      state.type = "continuous";
      state.continuous = { steerLow: nums[0], steerHigh: nums[1], speedLow: nums[2], speedHigh: nums[3] };
      return state;
    }
    if (keyword.toLowerCase() === "list") {
      const actions = text.slice(5).split(",").map((item) => item.split("/").map(Number));
      if (actions.every((p) => p.length === 2 && p.every(Number.isFinite))) {
        state.type = "discrete";
        state.actions = actions.map(([steer, speed]) => ({ steer, speed }));
        return state;
      }
    }
    return null;
  },

  // Polar coordinates of the graph: angle = steering (left is positive, drawn left), radius
  // = speed over the graph's top speed; (cx, cy) is the car, pointing up.
  point(steer, speed, geometry) {
    const angle = (steer * Math.PI) / 180;
    const r = (speed / geometry.topSpeed) * geometry.radius;
    return { x: geometry.cx - r * Math.sin(angle), y: geometry.cy - r * Math.cos(angle) };
  },

  // The steering angle and speed at a point of the graph (the inverse of `point`), kept
  // within the limits and rounded as the console rounds.
  actionAt(x, y, geometry, lim) {
    const clamp = (v, low, high) => Math.min(high, Math.max(low, v));
    const steer = (Math.atan2(geometry.cx - x, geometry.cy - y) * 180) / Math.PI;
    const speed = (Math.hypot(x - geometry.cx, y - geometry.cy) / geometry.radius) * geometry.topSpeed;
    return {
      steer: SlipActions.round2(clamp(steer, -lim.maxSteer, lim.maxSteer)),
      speed: SlipActions.round2(clamp(speed, lim.minSpeed, lim.maxSpeed)),
    };
  },
};

const SVG_NS = "http://www.w3.org/2000/svg";

function svgEl(tag, attrs, ...children) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
  for (const child of children) node.append(child);
  return node;
}

// The annular sector between two steering angles and two speeds, as an SVG path.
function sectorPath(steerLow, steerHigh, speedLow, speedHigh, g) {
  const p = (s, v) => SlipActions.point(s, v, g);
  const a = p(steerLow, speedHigh), b = p(steerHigh, speedHigh), c = p(steerHigh, speedLow), d = p(steerLow, speedLow);
  const R = (speedHigh / g.topSpeed) * g.radius, r = (speedLow / g.topSpeed) * g.radius;
  const large = steerHigh - steerLow > 180 ? 1 : 0;
  return `M${a.x},${a.y} A${R},${R} 0 ${large} 0 ${b.x},${b.y} L${c.x},${c.y} A${r},${r} 0 ${large} 1 ${d.x},${d.y} Z`;
}

// The continuous sector's drag handles: each moves one bound, from the middle of its edge.
const SECTOR_HANDLES = {
  steerLow: (c) => [c.steerLow, (c.speedLow + c.speedHigh) / 2],
  steerHigh: (c) => [c.steerHigh, (c.speedLow + c.speedHigh) / 2],
  speedLow: (c) => [(c.steerLow + c.steerHigh) / 2, c.speedLow],
  speedHigh: (c) => [(c.steerLow + c.steerHigh) / 2, c.speedHigh],
};

// Draw a state as the console's polar graph into `svg` (discrete: one numbered dot per
// action; continuous: the sector it covers, with a handle on each edge); `fixed` keeps the
// scale of an earlier drawing (while dragging). Returns the geometry drawn with.
function drawPolar(svg, state, lim, fixed = null) {
  const top = state.type === "continuous" ? state.continuous.speedHigh : Math.max(...state.actions.map((a) => a.speed));
  const g = fixed || { cx: 160, cy: 192, radius: 135, topSpeed: top > 0 ? top : lim.maxSpeed };
  const parts = [];
  for (let k = 1; k <= 4; k++) {
    const r = (k / 4) * g.radius;
    parts.push(svgEl("circle", { cx: g.cx, cy: g.cy, r, class: "polar-ring" }));
    parts.push(svgEl("text", { x: g.cx + 3, y: g.cy - r + 11, class: "polar-label" }, `${SlipActions.round2((g.topSpeed * k) / 4)} m/s`));
  }
  for (const steer of [-lim.maxSteer, -lim.maxSteer / 2, 0, lim.maxSteer / 2, lim.maxSteer]) {
    const end = SlipActions.point(steer, g.topSpeed, g);
    const label = SlipActions.point(steer, g.topSpeed * 1.1, g);
    parts.push(svgEl("line", { x1: g.cx, y1: g.cy, x2: end.x, y2: end.y, class: "polar-ray" }));
    parts.push(svgEl("text", { x: label.x, y: label.y, class: "polar-label", "text-anchor": "middle" }, `${steer}°`));
  }
  if (state.type === "continuous") {
    const c = state.continuous;
    parts.push(svgEl("path", { d: sectorPath(c.steerLow, c.steerHigh, c.speedLow, c.speedHigh, g), class: "polar-sector" }));
    for (const [bound, where] of Object.entries(SECTOR_HANDLES)) {
      const at = SlipActions.point(...where(c), g);
      parts.push(svgEl("circle", { cx: at.x, cy: at.y, r: 7, class: "polar-handle", "data-bound": bound }));
    }
  } else {
    const points = state.actions.map((a) => SlipActions.point(a.steer, a.speed, g));
    // Every arm under every dot: an arm to a faster action crosses slower dots of its angle.
    for (const at of points) parts.push(svgEl("line", { x1: g.cx, y1: g.cy, x2: at.x, y2: at.y, class: "polar-arm" }));
    points.forEach((at, i) => {
      parts.push(svgEl("circle", { cx: at.x, cy: at.y, r: 9, class: "polar-action", "data-index": i }));
      parts.push(svgEl("text", { x: at.x, y: at.y + 4, class: "polar-number", "text-anchor": "middle" }, String(i)));
    });
  }
  svg.replaceChildren(...parts);
  return g;
}

// A number input bound to `get`/`set` on the state.
function numberField(label, value, attrs, onInput) {
  const input = Slip.el("input", Object.assign({ type: "number", value, step: "any", "aria-label": label }, attrs));
  input.addEventListener("input", () => {
    if (input.value !== "" && Number.isFinite(Number(input.value))) onInput(Number(input.value));
  });
  return input;
}

function selectField(label, value, choices, onChange) {
  const select = Slip.el("select", { "aria-label": label }, ...choices.map((c) => Slip.el("option", { value: c, selected: c === value }, String(c))));
  select.addEventListener("change", () => onChange(Number(select.value)));
  return select;
}

// The builder: renders into `root`; `onChange(spec)` after every edit. Returns
// {spec(), setSpec(spec)} (setSpec returns false for a spec it cannot edit).
SlipActions.builder = function builder(root, rawLimits, defaults, onChange) {
  const lim = SlipActions.limits(rawLimits);
  const base = {
    type: "discrete",
    console: {
      maxSteer: lim.consoleDefault.max_steering_deg,
      steerGran: lim.consoleDefault.steering_granularity,
      maxSpeed: lim.consoleDefault.max_speed,
      speedGran: lim.consoleDefault.speed_granularity,
    },
    continuous: { steerLow: -lim.maxSteer, steerHigh: lim.maxSteer, speedLow: 0.5, speedHigh: lim.maxSpeed },
    actions: [],
  };
  let state = SlipActions.stateOf(defaults || "default", base) || base;
  if (!state.actions.length) {
    const b = state.console;
    state.actions = SlipActions.consoleActions(b.maxSteer, b.steerGran, b.maxSpeed, b.speedGran);
  }

  const svg = svgEl("svg", { viewBox: "0 0 320 200", class: "polar", role: "img", "aria-label": "Action space: steering angle as the angle, speed as the radius" });
  const specOut = Slip.el("code", { id: "action-spec" });
  const panel = Slip.el("div", { class: "action-panel" });
  const typeChoice = Slip.el(
    "div",
    { class: "choice-row", role: "radiogroup", "aria-label": "Action space type" },
    ...["discrete", "continuous"].map((t) =>
      Slip.el("label", {}, Slip.el("input", { type: "radio", name: "action-type", value: t, id: `action-type-${t}` }), " ", t),
    ),
  );
  typeChoice.addEventListener("change", (e) => {
    state.type = e.target.value;
    render();
  });

  let drag = null; // {geometry, index} or {geometry, bound} while a dot or handle is dragged
  const changed = (rebuildTable) => {
    drawPolar(svg, state, lim, drag && drag.geometry);
    specOut.textContent = SlipActions.specOf(state);
    if (rebuildTable) renderPanel();
    onChange(SlipActions.specOf(state));
  };

  // Drag an action's dot (discrete) or an edge of the sector (continuous) on the graph;
  // the table or the range fields follow. The scale holds still until the drag ends.
  const graphPoint = (event) => {
    const at = new DOMPoint(event.clientX, event.clientY).matrixTransform(svg.getScreenCTM().inverse());
    return SlipActions.actionAt(at.x, at.y, drag.geometry, lim);
  };
  svg.addEventListener("pointerdown", (event) => {
    const target = event.target;
    if (!target.matches(".polar-action, .polar-handle")) return;
    const geometry = drawPolar(svg, state, lim);
    drag = target.dataset.bound ? { geometry, bound: target.dataset.bound } : { geometry, index: Number(target.dataset.index) };
    svg.setPointerCapture(event.pointerId);
    event.preventDefault();
  });
  svg.addEventListener("pointermove", (event) => {
    if (!drag) return;
    const { steer, speed } = graphPoint(event);
    if (drag.bound) {
      const c = state.continuous;
      if (drag.bound === "steerLow") c.steerLow = Math.min(steer, c.steerHigh);
      if (drag.bound === "steerHigh") c.steerHigh = Math.max(steer, c.steerLow);
      if (drag.bound === "speedLow") c.speedLow = Math.min(speed, c.speedHigh);
      if (drag.bound === "speedHigh") c.speedHigh = Math.max(speed, c.speedLow);
    } else {
      Object.assign(state.actions[drag.index], { steer, speed });
    }
    changed(true);
  });
  const endDrag = () => {
    if (!drag) return;
    drag = null;
    changed(false);
  };
  svg.addEventListener("pointerup", endDrag);
  svg.addEventListener("pointercancel", endDrag);

  const fromConsole = () => {
    const b = state.console;
    state.actions = SlipActions.consoleActions(b.maxSteer, b.steerGran, b.maxSpeed, b.speedGran);
    changed(true);
  };

  function discretePanel() {
    const b = state.console;
    const settings = Slip.el(
      "div",
      { class: "fields" },
      Slip.el("label", {}, "Maximum steering angle (°)", numberField("Maximum steering angle", b.maxSteer, { id: "max-steer", min: 1, max: lim.maxSteer }, (v) => { b.maxSteer = v; fromConsole(); })),
      Slip.el("label", {}, "Steering angle granularity", selectField("Steering angle granularity", b.steerGran, lim.steerGrans, (v) => { b.steerGran = v; fromConsole(); })),
      Slip.el("label", {}, "Maximum speed (m/s)", numberField("Maximum speed", b.maxSpeed, { id: "max-speed", min: lim.minSpeed, max: lim.maxSpeed }, (v) => { b.maxSpeed = v; fromConsole(); })),
      Slip.el("label", {}, "Speed granularity", selectField("Speed granularity", b.speedGran, lim.speedGrans, (v) => { b.speedGran = v; fromConsole(); })),
    );
    const rows = state.actions.map((a, i) =>
      Slip.el(
        "tr",
        {},
        Slip.el("td", {}, String(i)),
        Slip.el("td", {}, numberField(`Action ${i} steering angle`, a.steer, { min: -lim.maxSteer, max: lim.maxSteer }, (v) => { a.steer = v; changed(false); })),
        Slip.el("td", {}, numberField(`Action ${i} speed`, a.speed, { min: lim.minSpeed, max: lim.maxSpeed }, (v) => { a.speed = v; changed(false); })),
        Slip.el("td", {}, removeButton(i)),
      ),
    );
    const table = Slip.el(
      "table",
      { id: "action-table", class: "board compact" },
      Slip.el("thead", {}, Slip.el("tr", {}, Slip.el("th", {}, "#"), Slip.el("th", {}, "Steering (°)"), Slip.el("th", {}, "Speed (m/s)"), Slip.el("th", {}, ""))),
      Slip.el("tbody", {}, ...rows),
    );
    const add = Slip.el("button", { type: "button", id: "action-add", disabled: lim.maxActions !== undefined && state.actions.length >= lim.maxActions }, "Add an action");
    add.addEventListener("click", () => {
      state.actions.push({ steer: 0, speed: state.console.maxSpeed });
      changed(true);
    });
    return [settings, table, add];
  }

  function removeButton(i) {
    const button = Slip.el("button", { type: "button", class: "link", "aria-label": `Remove action ${i}`, disabled: state.actions.length <= 1 }, "remove");
    button.addEventListener("click", () => {
      state.actions.splice(i, 1);
      changed(true);
    });
    return button;
  }

  function continuousPanel() {
    const c = state.continuous;
    const field = (label, key, min, max) =>
      Slip.el("label", {}, label, numberField(label, c[key], { id: `cont-${key}`, min, max }, (v) => { c[key] = v; changed(false); }));
    return [
      Slip.el(
        "div",
        { class: "fields" },
        field("Steering angle from (°)", "steerLow", -lim.maxSteer, lim.maxSteer),
        field("Steering angle to (°)", "steerHigh", -lim.maxSteer, lim.maxSteer),
        field("Speed from (m/s)", "speedLow", lim.minSpeed, lim.maxSpeed),
        field("Speed to (m/s)", "speedHigh", lim.minSpeed, lim.maxSpeed),
      ),
    ];
  }

  function renderPanel() {
    panel.replaceChildren(...(state.type === "continuous" ? continuousPanel() : discretePanel()));
  }

  function render() {
    root.querySelector(`#action-type-${state.type}`).checked = true;
    renderPanel();
    changed(false);
  }

  root.replaceChildren(
    typeChoice,
    Slip.el("div", { class: "action-builder" }, panel, Slip.el("figure", { class: "polar-figure" }, svg, Slip.el("figcaption", { class: "muted" }, "Spec: ", specOut))),
  );
  render();
  return {
    spec: () => SlipActions.specOf(state),
    setSpec(spec) {
      const parsed = SlipActions.stateOf(spec, state);
      if (parsed === null) return false;
      state = parsed;
      render();
      return true;
    },
  };
};

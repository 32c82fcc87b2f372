// /garage/new: create a model (DeepRacer's "create model" form) on the training-jobs API.
// The catalogue (GET /api/garage/catalogue) supplies tracks, race types, sensors, action-space
// limits, hyperparameters, recipes, reward samples, defaults and limits; Validate sends the
// whole body to POST /api/training-jobs/check, Train to POST /api/training-jobs.
"use strict";

const Create = {
  // The job body of a form state (league/schemas.py TrainingJobCreate).
  jobBody(form) {
    const body = {
      name: form.name.trim(),
      reward_source: form.reward,
      options: {
        track: form.track,
        direction: form.direction,
        race_type: form.raceType,
        ...form.raceSettings,
        sensors: form.sensors.join(","),
        action_space: form.actionSpace,
      },
      minutes: form.minutes,
    };
    if (form.description.trim()) body.description = form.description.trim();
    if (form.recipe) body.recipe = form.recipe;
    if (form.hyperparameters && Object.keys(form.hyperparameters).length) body.hyperparameters = form.hyperparameters;
    if (form.anchor) body.options.anchor = "pursuit";
    if (form.anchor && form.anchorWeight !== 1) body.options.anchor_weight = form.anchorWeight;
    if (form.alsoTracks.length) body.options.also_tracks = form.alsoTracks.join(",");
    if (form.alsoTracks.length && form.evalAlsoTracks) body.options.eval_also_tracks = true;
    if (form.cloneOf) body.clone_of = form.cloneOf;
    return body;
  },

  // The imitation recipe of a race type ("fast start"): the recipe named after it; null
  // when there is none, or it needs a parent run and this is not a clone.
  fastStartRecipe(raceType, recipes, cloning) {
    const recipe = recipes.find((r) => r.name === raceType);
    return recipe && (!recipe.needs_parent || cloning) ? recipe : null;
  },

  // Which sensors may not be added to `selected` (no allowed combination holds them all),
  // and whether `selected` is itself an allowed combination.
  sensorState(selected, combinations) {
    const fits = (set) => combinations.some((c) => set.every((s) => c.includes(s)));
    const choices = [...new Set(combinations.flat())];
    const blocked = choices.filter((s) => !selected.includes(s) && !fits([...selected, s]));
    const valid = combinations.some((c) => c.length === selected.length && fits(selected));
    return { blocked, valid };
  },

  // The settings (hyperparameters, a race type's) that differ from their defaults (the
  // rest stay the recipe's or the league's), from {name: input text}; `key` names a spec.
  changedValues(values, specs, key = "name") {
    const changed = {};
    for (const spec of specs) {
      const text = values[spec[key]];
      if (text === undefined || text === "") continue;
      const value = typeof spec.default === "number" ? Number(text) : text;
      if (value !== spec.default) changed[spec[key]] = value;
    }
    return changed;
  },
};

const $ = (id) => document.getElementById(id);
let catalogue = null;
let editor = null;
let actions = null;
const cloneOf = Number(new URLSearchParams(window.location.search).get("clone")) || null;

function trackCard(track) {
  const id = `track-${track.name}`;
  const facts = [
    `${track.length.toFixed(1)} m long`,
    `${track.width.toFixed(2)} m wide`,
    track.direction === "cw" ? "clockwise" : "counter-clockwise",
    track.physical_limit_lap_s ? `physical limit ${Slip.ms(track.physical_limit_lap_s * 1000)}` : null,
  ].filter(Boolean);
  return Slip.el(
    "label",
    { class: "pick-card", for: id },
    Slip.el("input", { type: "radio", name: "track", id, value: track.name }),
    Slip.el("img", { src: track.thumbnail_url, alt: "", width: 120, height: 80, loading: "lazy" }),
    Slip.el("span", { class: "pick-body" }, Slip.el("strong", {}, track.display_name), Slip.el("span", { class: "muted" }, facts.join(" · "))),
  );
}

function raceTypeCard(type) {
  const settings = type.settings.map((s) => `${s.help}: ${s.default}`);
  return Slip.el(
    "label",
    { class: "pick-card", for: `race-${type.name}` },
    Slip.el("input", { type: "radio", name: "race_type", id: `race-${type.name}`, value: type.name }),
    Slip.el("span", { class: "pick-body" }, Slip.el("strong", {}, type.label), Slip.el("span", {}, type.description), Slip.el("span", { class: "muted" }, settings.join(" · "))),
  );
}

function checked(name) {
  const node = document.querySelector(`input[name="${name}"]:checked`);
  return node ? node.value : null;
}

function setChecked(name, value) {
  const node = document.querySelector(`input[name="${name}"][value="${CSS.escape(String(value))}"]`);
  if (node) node.checked = true;
  return Boolean(node);
}

function selectedSensors() {
  return Array.from(document.querySelectorAll('input[name="sensor"]:checked'), (n) => n.value);
}

// Disable the sensors that cannot join the chosen ones; say why when the set is not allowed.
function updateSensors() {
  const { blocked, valid } = Create.sensorState(selectedSensors(), catalogue.sensors.combinations);
  for (const box of document.querySelectorAll('input[name="sensor"]')) {
    box.disabled = blocked.includes(box.value);
    box.closest("label").title = box.disabled ? catalogue.sensors.rules : "";
  }
  $("sensor-note").textContent = valid ? catalogue.sensors.rules : "Not a combination a car can carry. " + catalogue.sensors.rules;
  $("sensor-note").className = valid ? "muted" : "error";
}

// The chosen track's own direction; it cannot also be a further track.
function updateTrackDirection() {
  const track = catalogue.tracks.find((t) => t.name === checked("track"));
  if (track) $("direction").value = track.direction;
  for (const box of document.querySelectorAll('input[name="also_track"]')) {
    box.disabled = box.value === checked("track");
    if (box.disabled) box.checked = false;
  }
}

function alsoTrackBox(track) {
  const id = `also-track-${track.name}`;
  return Slip.el("label", { for: id }, Slip.el("input", { type: "checkbox", name: "also_track", id, value: track.name }), " ", track.display_name);
}

function raceSettingSpecs() {
  const type = catalogue.race_types.find((t) => t.name === checked("race_type"));
  return type ? type.settings : [];
}

// The chosen race type's own settings (boxes; bots, their speed and lane changes), each at
// `values[option]` or its league default.
function updateRaceSettings(values = {}) {
  const fields = raceSettingSpecs().map((spec) => {
    const id = `race-${spec.option}`;
    const whole = Number.isInteger(spec.default);
    const input = Slip.el("input", {
      id,
      name: spec.option,
      type: "number",
      step: whole ? 1 : "any",
      min: spec.min,
      max: spec.max,
      value: values[spec.option] ?? spec.default,
    });
    const help = spec.help.charAt(0).toUpperCase() + spec.help.slice(1);
    return Slip.el("label", { for: id }, Slip.el("span", {}, help), input, Slip.el("small", { class: "muted" }, `league default ${spec.default}`));
  });
  $("race-settings").replaceChildren(...fields);
}

function raceSettingValues() {
  const values = {};
  for (const spec of raceSettingSpecs()) values[spec.option] = $(`race-${spec.option}`).value;
  return Create.changedValues(values, raceSettingSpecs(), "option");
}

function updateFastStart() {
  const raceType = checked("race_type");
  const recipe = Create.fastStartRecipe(raceType, catalogue.recipes, Boolean(cloneOf));
  const box = $("fast-start");
  box.disabled = !recipe;
  if (!recipe) box.checked = false;
  $("fast-start-note").textContent = recipe
    ? `Uses the ${recipe.name} recipe: the car first imitates the league's scripted driver, then learns from your reward (${recipe.summary}).`
    : `No fast start for ${raceType}${cloneOf ? "" : " unless you clone a run"}.`;
}

// The anchor (PPO held near the scripted driver) is for a clone, and not with fast start:
// imitation already copies the driver.
function updateAnchor() {
  const box = $("anchor");
  box.disabled = !cloneOf || $("fast-start").checked;
  if (box.disabled) box.checked = false;
  $("anchor-weight").disabled = !box.checked;
  $("anchor-note").textContent = !cloneOf
    ? "For a clone: it keeps what the cloned run learned."
    : $("fast-start").checked
      ? "Not with fast start, which already imitates the scripted driver."
      : "Your reward trains the car, and every update is also pulled toward the league's scripted driver: what a fast-start run learned by imitation is kept while the reward improves on it. How strongly: 1 by default; 0 leaves your reward alone, more keeps the car closer to the driver.";
}

function hyperparameterField(spec) {
  const id = `hp-${spec.name}`;
  const input = spec.choices
    ? Slip.el("select", { id, name: spec.name }, ...spec.choices.map((c) => Slip.el("option", { value: c, selected: c === spec.default }, String(c))))
    : Slip.el("input", { id, name: spec.name, type: "number", step: "any", value: spec.default, min: spec.min, max: spec.max });
  const range = spec.choices ? "" : ` (${spec.min ?? "…"} to ${spec.max ?? "…"})`;
  return Slip.el("label", { for: id, title: spec.help || "" }, Slip.el("span", {}, spec.name, Slip.el("span", { class: "muted" }, range)), input, Slip.el("small", { class: "muted" }, spec.help || ""));
}

function hyperparameterValues() {
  const values = {};
  for (const spec of catalogue.hyperparameters) values[spec.name] = $(`hp-${spec.name}`).value;
  return values;
}

function formState() {
  const fast = $("fast-start").checked ? Create.fastStartRecipe(checked("race_type"), catalogue.recipes, Boolean(cloneOf)) : null;
  return {
    name: $("model-name").value,
    description: $("model-description").value,
    track: checked("track"),
    alsoTracks: Array.from(document.querySelectorAll('input[name="also_track"]:checked'), (n) => n.value),
    evalAlsoTracks: $("eval-also-tracks").checked,
    direction: $("direction").value,
    raceType: checked("race_type"),
    raceSettings: raceSettingValues(),
    sensors: selectedSensors(),
    actionSpace: actions.spec(),
    reward: editor.getValue(),
    hyperparameters: Create.changedValues(hyperparameterValues(), catalogue.hyperparameters),
    minutes: Number($("minutes").value),
    recipe: fast ? fast.name : null,
    anchor: $("anchor").checked,
    anchorWeight: Number($("anchor-weight").value),
    cloneOf,
  };
}

// Show a refusal; mark the reward's line when the message names one.
function refuse(answer) {
  const text = Slip.errorText(answer);
  Slip.say("validate-result", text, "error");
  const line = Slip.lineOf(text);
  if (line !== null && /reward/.test(text)) editor.markLine(line, text);
}

async function send(path) {
  editor.clearMarks();
  if (!Slip.token()) {
    Slip.say("validate-result", "Paste your API token (top right) first.", "error");
    return null;
  }
  Slip.say("validate-result", path.endsWith("/check") ? "Validating…" : "Queuing…", "");
  const answer = await Slip.api(path, {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(Create.jobBody(formState())),
  });
  if (!answer.ok) refuse(answer);
  return answer.ok ? answer : null;
}

async function validate() {
  if (await send("/api/training-jobs/check")) Slip.say("validate-result", "Valid: this model can train.", "ok");
}

async function train(event) {
  event.preventDefault();
  const answer = await send("/api/training-jobs");
  if (answer) window.location.assign(`/garage/jobs/${answer.body.id}`);
}

function loadSample() {
  const sample = catalogue.reward_samples.find((s) => s.name === $("reward-sample").value);
  if (sample) {
    editor.setValue(sample.source);
    editor.clearMarks();
  }
}

// Fill the form from a job (cloning it).
function fillFrom(job) {
  const o = job.options || {};
  $("model-name").value = `${job.name}-clone`.slice(0, 64);
  if (o.track) setChecked("track", o.track);
  updateTrackDirection();
  if (o.direction) $("direction").value = o.direction;
  for (const name of String(o.also_tracks || "").split(",")) if (name) setChecked("also_track", name);
  $("eval-also-tracks").checked = Boolean(o.eval_also_tracks);
  if (job.description) $("model-description").value = job.description;
  if (o.race_type) setChecked("race_type", o.race_type);
  updateRaceSettings(o);
  if (o.sensors) {
    const wanted = String(o.sensors).split(",");
    for (const box of document.querySelectorAll('input[name="sensor"]')) box.checked = wanted.includes(box.value);
  }
  if (o.action_space) actions.setSpec(o.action_space);
  for (const [name, value] of Object.entries(job.hyperparameters || {})) {
    const input = $(`hp-${name}`);
    if (input) input.value = value;
  }
  $("minutes").value = job.minutes;
  if (job.reward_source) editor.setValue(job.reward_source);
  updateSensors();
  updateFastStart();
  // A clone of an imitation (fast start) run learns from the reward, held near the driver.
  $("fast-start").checked = false;
  updateAnchor();
  $("anchor").checked = !$("anchor").disabled && (Boolean(job.recipe) || Boolean(o.anchor));
  if (o.anchor_weight !== undefined) $("anchor-weight").value = o.anchor_weight;
  updateAnchor();
  $("clone-note").textContent =
    `Cloning training job ${job.id} (${job.name}): training starts from its run.` +
    (job.reward_source ? "" : " Its reward function is not shown here: pick or write one below.");
}

function build() {
  const d = catalogue.defaults;
  $("tracks").replaceChildren(...catalogue.tracks.map(trackCard));
  $("also-tracks").append(...catalogue.tracks.map(alsoTrackBox));
  $("race-types").replaceChildren(...catalogue.race_types.map(raceTypeCard));
  $("sensors").replaceChildren(
    ...catalogue.sensors.choices.map((s) => Slip.el("label", {}, Slip.el("input", { type: "checkbox", name: "sensor", value: s }), " ", s.replace(/_/g, " "))),
  );
  $("reward-sample").replaceChildren(...catalogue.reward_samples.map((s) => Slip.el("option", { value: s.name }, s.title)));
  $("hyperparameters").replaceChildren(...catalogue.hyperparameters.map(hyperparameterField));
  $("minutes").max = catalogue.limits.max_minutes;
  $("minutes").value = Math.min(d.minutes, catalogue.limits.max_minutes);
  $("minutes-note").textContent = `At most ${catalogue.limits.max_minutes} minutes.`;
  setChecked("track", d.track) || document.querySelector('input[name="track"]').click();
  updateTrackDirection();
  if (d.direction) $("direction").value = d.direction;
  setChecked("race_type", d.race_type);
  updateRaceSettings();
  const wanted = String(d.sensors).split(",");
  for (const box of document.querySelectorAll('input[name="sensor"]')) box.checked = wanted.includes(box.value);
  editor = SlipEditor.create($("reward"));
  actions = SlipActions.builder($("action-space"), catalogue.action_space, d.action_space, () => {});
  loadSample();
  updateSensors();
  updateFastStart();
  updateAnchor();

  $("tracks").addEventListener("change", updateTrackDirection);
  $("race-types").addEventListener("change", () => {
    updateRaceSettings();
    updateFastStart();
    updateAnchor();
  });
  $("fast-start").addEventListener("change", updateAnchor);
  $("anchor").addEventListener("change", updateAnchor);
  $("sensors").addEventListener("change", updateSensors);
  $("reward-load").addEventListener("click", loadSample);
  $("validate").addEventListener("click", validate);
  $("create-form").addEventListener("submit", train);
}

async function start() {
  const answer = await Slip.getPatiently("/api/garage/catalogue");
  if (!answer.ok) {
    Slip.say("validate-result", "The garage's catalogue could not be loaded: " + Slip.errorText(answer), "error");
    return;
  }
  catalogue = answer.body;
  build();
  if (!Slip.token()) Slip.say("validate-result", "Paste your API token (top right) to validate and train.", "");
  if (cloneOf) {
    const job = await Slip.api(`/api/training-jobs/${cloneOf}`);
    if (job.ok) fillFrom(job.body);
    else Slip.say("validate-result", Slip.errorText(job), "error");
  }
  $("create-form").dataset.ready = "true";
}

start();

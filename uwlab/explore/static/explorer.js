// uwlab design explorer: the page's state is the text of every field (as typed after `--set KEY=`); every change
// sends {"config": {}, "text": {...}} to /api/view and shows what comes back. All numbers, their formatting and
// the warnings come from the server (uwlab.experiments.design.readout); this script only places them.
"use strict";

const $ = (selector, root = document) => root.querySelector(selector);
const $$ = (selector, root = document) => Array.from(root.querySelectorAll(selector));
const valueInputs = () => $$(".value[data-key]");
const inputFor = (key) => $(`.value[data-key="${CSS.escape(key)}"]`);
const fieldFor = (key) => $(`.field[data-key="${CSS.escape(key)}"]`);

let SCHEMA = null;          // /api/schema
let lastView = null;        // last good /api/view answer
let inFlight = false, dirty = false, typingTimer = null;
const PLOT_CONFIG = { displaylogo: false, responsive: true, modeBarButtonsToRemove: ["lasso2d", "select2d"] };

// ---- talking to the server -----------------------------------------------------------------------------------
// The XSRF token the server set as a cookie, repeated in a header (uwlab/explore/security.py: double submit).
const xsrfToken = () => (document.cookie.match(/(?:^|;\s*)_xsrf=([^;]*)/) || [])[1] || "";

async function api(path, body) {
  const response = await fetch(path, body === undefined ? {} : {
    method: "POST", headers: { "Content-Type": "application/json", "X-XSRF-Token": xsrfToken() },
    body: JSON.stringify(body) });
  const type = response.headers.get("Content-Type") || "";
  const data = type.includes("json") ? await response.json() : await response.text();
  if (!response.ok) {
    const error = new Error(data && data.error ? data.error : `HTTP ${response.status}`);
    error.key = data && data.key;
    throw error;
  }
  return data;
}

function texts() {
  const out = {};
  for (const input of valueInputs()) {
    if (input.value.trim() !== "") out[input.dataset.key] = input.value.trim();
  }
  return out;
}
const designBody = () => ({ config: {}, text: texts() });

function setTexts(values) {
  for (const input of valueInputs()) input.value = values[input.dataset.key] ?? "";
  syncPresets();
  syncSliders();
}

// ---- the URL holds the design (shareable) -----------------------------------------------------------------
function designFromUrl() {
  const params = new URLSearchParams(location.search);
  const found = {};
  for (const [key, value] of params) if (key.includes(".")) found[key] = value;
  return Object.keys(found).length ? found : null;
}
function writeUrl() {
  const params = new URLSearchParams(texts());
  history.replaceState(null, "", `${location.pathname}?${params}`);
}

// ---- evaluation -------------------------------------------------------------------------------------------
function schedule(delay = 0) {
  clearTimeout(typingTimer);
  typingTimer = setTimeout(update, delay);
}

async function update() {
  if (inFlight) { dirty = true; return; }
  inFlight = true; dirty = false;
  writeUrl();
  const started = performance.now();
  setStatus("evaluating…");
  try {
    const view = await api("/api/view", designBody());
    lastView = view;
    showError(null);
    showReadout(view);
    showFigures(view.figures);
    fillOutputChoices(view.outputs);
    setStatus(`evaluated in ${Math.round(performance.now() - started)} ms`);
    if (sweepShown) runSweep();
  } catch (error) {
    showError(error);
    setStatus("error");
  } finally {
    inFlight = false;
    if (dirty) update();
  }
}

function setStatus(text) { $("#status").textContent = text; }

function showError(error) {
  const banner = $("#error");
  $$(".field.error").forEach((f) => { f.classList.remove("error"); $(".field-message", f).hidden = true; });
  $$(".readout-card, .budget-card, section.figures").forEach((el) => el.classList.toggle("stale", !!error));
  if (!error) { banner.hidden = true; return; }
  banner.hidden = false;
  banner.textContent = "⚠ " + error.message;
  const field = error.key && fieldFor(error.key);
  if (field) {
    field.classList.add("error");
    const message = $(".field-message", field);
    message.textContent = error.message;
    message.hidden = false;
  }
}

function cell(row, text, className) {
  const td = row.insertCell();
  td.textContent = text;
  if (className) td.className = className;
  return td;
}

function showReadout(view) {
  const notes = {};
  for (const w of view.warnings) (notes[w.outputs[0]] ||= []).push(w);
  const warnedOutputs = new Set(view.warnings.flatMap((w) => w.outputs));
  const old = {};
  for (const tr of $$("#readout tr")) old[tr.dataset.key] = tr.dataset.text;
  const body = $("#readout tbody");
  body.replaceChildren();
  for (const row of view.rows) {
    const tr = body.insertRow();
    tr.dataset.key = row.key;
    tr.dataset.text = row.text;
    if (warnedOutputs.has(row.key)) tr.classList.add("warn");
    cell(tr, row.label, "label");
    const num = cell(tr, row.text, "num");
    if (old[row.key] !== undefined && old[row.key] !== row.text) num.classList.add("changed");
    cell(tr, row.unit, "unit");
    const note = cell(tr, "", "note");
    for (const w of notes[row.key] || []) {
      const badge = document.createElement("span");
      badge.className = "badge";
      badge.dataset.kind = w.kind;
      badge.textContent = "⚠ " + w.message;
      note.append(badge, " ");
    }
  }
  $$(".field.warned").forEach((f) => f.classList.remove("warned"));
  for (const w of view.warnings) {
    for (const key of w.inputs) {
      const field = fieldFor(key);
      if (field && texts()[key] !== undefined) { field.classList.add("warned"); field.title = w.message; }
    }
  }
  const budget = $("#budget tbody");
  budget.replaceChildren();
  if (view.budget) {
    for (const row of view.budget.rows) {
      const tr = budget.insertRow();
      if (row.key === view.budget.worst) tr.classList.add("worst");
      cell(tr, row.label, "label"); cell(tr, row.text, "num");
      cell(tr, row.key === view.budget.worst ? "← most" : "", "note");
      if (row.key === view.budget.worst) tr.title = "the stage that limits the signal most";
    }
    const tr = budget.insertRow();
    tr.classList.add("total");
    cell(tr, "total (lights → electrons)", "label"); cell(tr, view.budget.total, "num"); cell(tr, "", "note");
  }
}

function plot(id, figure) {
  const el = document.getElementById(id);
  if (!el) return;
  if (!figure) { Plotly.purge(el); return; }
  const config = id === "fig-budget" ? { ...PLOT_CONFIG, displayModeBar: false } : PLOT_CONFIG;
  Plotly.react(el, figure.data, { ...figure.layout, template: SCHEMA.template, autosize: true }, config);
}

function showFigures(figures) {
  for (const [name, figure] of Object.entries(figures)) plot(`fig-${name}`, figure);
}

// ---- presets (components from configs/ and user profiles) ----------------------------------------------------
function fillPresets() {
  for (const select of $$("select.preset")) {
    const presets = SCHEMA.presets[select.dataset.section];
    if (!presets || !presets.length) continue;
    select.hidden = false;
    select.replaceChildren(new Option(`${select.dataset.section}: choose a component…`, ""));
    presets.forEach((p, i) => select.add(new Option((p.user ? "★ " : "") + p.label, String(i))));
  }
  for (const [key, words] of Object.entries(SCHEMA.suggestions)) {
    const input = inputFor(key);
    if (!input) continue;
    let list = document.getElementById(`s-${key}`);
    if (!list) { list = document.createElement("datalist"); list.id = `s-${key}`; input.after(list); input.setAttribute("list", list.id); }
    const have = new Set($$("option", list).map((o) => o.value));
    for (const word of words) if (!have.has(word)) list.append(new Option(word, word));
  }
}

function syncPresets() {
  const current = texts();
  for (const select of $$("select.preset")) {
    const presets = SCHEMA && SCHEMA.presets[select.dataset.section];
    if (!presets) continue;
    const index = presets.findIndex((p) => Object.entries(p.text).every(([k, v]) => (current[k] ?? "") === v));
    select.value = index >= 0 ? String(index) : "";
  }
}

function applyPreset(select) {
  const preset = SCHEMA.presets[select.dataset.section][Number(select.value)];
  if (!preset) return;
  for (const [key, value] of Object.entries(preset.text)) {
    const input = inputFor(key);
    if (input) input.value = value;
  }
  syncSliders();
  schedule();
}

// ---- sliders: a log window of two decades around the value, or the whole range when it is short -------------
function sliderScale(input, value) {
  const lo = Number(input.dataset.lo), hi = Number(input.dataset.hi);
  const linear = hi - lo <= 100 && Math.abs(value) >= (hi - lo) / 1000;
  if (linear) return { linear, a: lo, b: hi };
  const a = Math.max(value / 10, lo > 0 ? lo : value / 10), b = Math.min(value * 10, hi);
  return { linear, a, b };
}

function numberIn(text) {
  const n = Number(text);
  return text.trim() !== "" && Number.isFinite(n) ? n : null;
}

function syncSliders() {
  for (const slider of $$(".slider")) {
    const input = inputFor(slider.dataset.key);
    const value = numberIn(input.value) ?? numberIn(input.dataset.default ?? "");
    slider.disabled = value === null || (value <= 0 && !(Number(input.dataset.hi) - Number(input.dataset.lo) <= 100));
    if (slider.disabled) continue;
    const scale = sliderScale(input, value);
    slider.scale = scale;
    const t = scale.linear ? (value - scale.a) / (scale.b - scale.a) : Math.log(value / scale.a) / Math.log(scale.b / scale.a);
    slider.value = String(Math.round(1000 * Math.min(1, Math.max(0, t))));
  }
}

function onSlide(slider) {
  const input = inputFor(slider.dataset.key);
  const { linear, a, b } = slider.scale;
  const t = Number(slider.value) / 1000;
  let value = linear ? a + t * (b - a) : a * Math.pow(b / a, t);
  value = input.dataset.integer === "1" ? Math.round(value) : Number(value.toPrecision(4));
  input.value = String(value);
  schedule();
}

// ---- save, load, share, reset -----------------------------------------------------------------------------
async function save() {
  try {
    const text = await api("/api/toml", designBody());
    const link = document.createElement("a");
    link.href = URL.createObjectURL(new Blob([text], { type: "application/toml" }));
    link.download = "design.toml";
    document.body.append(link);
    link.click();
    link.remove();
    setStatus("saved design.toml");
  } catch (error) { showError(error); }
}

async function load(file) {
  try {
    const answer = await api("/api/load", { toml: await file.text(), name: file.name });
    setTexts(answer.text);
    setStatus(`loaded ${file.name}`);
    schedule();
  } catch (error) {
    showError({ message: `${file.name}: ${error.message}`, key: error.key });
  }
}

function share() {
  writeUrl();
  $("#share-box").hidden = false;
  const box = $("#share-url");
  box.value = location.href;
  box.select();
  if (navigator.clipboard) navigator.clipboard.writeText(location.href).then(() => setStatus("link copied"), () => {});
}

async function reset() {
  setTexts((await api("/api/config")).text);
  schedule();
}

async function addProfile() {
  const message = $("#profile-message");
  try {
    const answer = await api("/api/profile", { path: $("#profile-path").value.trim() });
    SCHEMA.presets = answer.presets;
    fillPresets();
    for (const [key, value] of Object.entries(answer.text)) { const input = inputFor(key); if (input) input.value = value; }
    message.hidden = true;
    setStatus(`added ${answer.section} profile ${answer.label}`);
    syncSliders();
    schedule();
  } catch (error) {
    message.textContent = error.message;
    message.hidden = false;
  }
}

// ---- sweep ----------------------------------------------------------------------------------------------------
let sweepShown = false, sweepInFlight = false;
const keyLabel = (key) => key;

function fillKeySelects() {
  const fields = SCHEMA.sections.flatMap((s) => s.fields);
  const sweepKeys = fields.filter((f) => f.grid || f.words.length || f.text);
  const numericKeys = fields.filter((f) => f.grid);
  for (const select of [$("#sweep-key-1"), $("#sweep-key-2")]) {
    for (const f of sweepKeys) select.add(new Option(keyLabel(f.key), f.key));
  }
  $("#sweep-key-1").value = "lens.f_number";
  $("#sweep-key-2").value = "";
  for (const select of $$(".objective-key")) for (const f of numericKeys) select.add(new Option(f.key, f.key));
  $$(".objective-key")[0].value = "light.luminous_flux_lm";
  $$(".objective-key")[1].value = "lens.f_number";
}

function rangeFor(select, input) {
  const key = select.value;
  if (!key) { input.value = ""; return; }
  const field = SCHEMA.sections.flatMap((s) => s.fields).find((f) => f.key === key);
  const value = numberIn(inputFor(key).value) ?? numberIn(inputFor(key).dataset.default ?? "");
  if (field.grid && value !== null && value > 0) {
    let lo = value / 4, hi = value * 4;
    if (field.number) { lo = Math.max(lo, field.number.lo); hi = Math.min(hi, field.number.hi); }
    const step = Number(((hi - lo) / 50).toPrecision(2));
    input.value = `${Number(lo.toPrecision(3))}:${Number(hi.toPrecision(3))}:${step}`;
  } else {
    const words = field.words.length ? field.words : (SCHEMA.suggestions[key] || []);
    input.value = words.join(",");
  }
}

function fillOutputChoices(outputs) {
  const select = $("#sweep-output");
  const keep = select.value || "snr_db";
  const names = outputs.map((o) => o.name).join("|");
  if (select.dataset.names !== names) {
    select.replaceChildren(...outputs.map((o) => new Option(`${o.name} — ${o.label}${o.unit ? " [" + o.unit + "]" : ""}`, o.name)));
    select.dataset.names = names;
    for (const req of $$("#solve-require select.output")) fillOutputSelect(req, req.value);
  }
  select.value = outputs.some((o) => o.name === keep) ? keep : outputs[0].name;
}

async function runSweep() {
  if (sweepInFlight) return;
  sweepInFlight = true;
  const grid = {};
  for (const i of [1, 2]) {
    const key = $(`#sweep-key-${i}`).value;
    if (key) grid[key] = $(`#sweep-range-${i}`).value;
  }
  const started = performance.now();
  $("#sweep-status").textContent = "sweeping…";
  try {
    const answer = await api("/api/sweep", { ...designBody(), grid, output: $("#sweep-output").value });
    $("#sweep-error").hidden = true;
    plot("fig-sweep", answer.figure);
    sweepShown = true;
    $("#sweep-status").textContent = `${answer.points} points in ${Math.round(performance.now() - started)} ms`;
  } catch (error) {
    $("#sweep-error").hidden = false;
    $("#sweep-error").textContent = "⚠ " + error.message;
    $("#sweep-status").textContent = "";
  } finally {
    sweepInFlight = false;
  }
}

// ---- inverse design ----------------------------------------------------------------------------------------
function fillOutputSelect(select, keep) {
  const outputs = lastView ? lastView.outputs : [];
  const want = keep || select.dataset.keep;
  select.replaceChildren(...outputs.map((o) => new Option(`${o.name}${o.unit ? " [" + o.unit + "]" : ""}`, o.name)));
  if (want) select.value = want;
}

function addFree(key = "", lo = "", hi = "") {
  const row = document.createElement("div");
  row.className = "panel-row free";
  const select = document.createElement("select");
  select.className = "key-select";
  for (const f of SCHEMA.sections.flatMap((s) => s.fields).filter((f) => f.grid)) select.add(new Option(f.key, f.key));
  select.value = key;
  row.append(select, numInput("lo", lo), "…", numInput("hi", hi), removeButton(row));
  $("#solve-free").append(row);
}

function addRequirement(output = "snr_db", op = ">=", value = "") {
  const row = document.createElement("div");
  row.className = "panel-row requirement";
  const select = document.createElement("select");
  select.className = "output key-select";
  select.dataset.keep = output;
  fillOutputSelect(select, output);
  const operator = document.createElement("select");
  operator.className = "op";
  operator.add(new Option(">=")); operator.add(new Option("<="));
  operator.value = op;
  row.append(select, operator, numInput("value", value), removeButton(row));
  $("#solve-require").append(row);
}

function numInput(className, value) {
  const input = document.createElement("input");
  input.className = `num ${className}`;
  input.value = value;
  input.spellcheck = false;
  return input;
}

function removeButton(row) {
  const button = document.createElement("button");
  button.className = "small";
  button.textContent = "−";
  button.addEventListener("click", () => row.remove());
  return button;
}

async function runSolve() {
  const free = $$("#solve-free .free").map((r) => `${$("select", r).value}=${$(".lo", r).value}:${$(".hi", r).value}`);
  const require = $$("#solve-require .requirement").map((r) => `${$(".output", r).value} ${$(".op", r).value} ${$(".value", r).value}`);
  const objectives = $$("#solve-objectives .panel-row")
    .map((r) => [$(".sense", r).value, $(".objective-key", r).value])
    .filter(([sense]) => sense).map(([sense, key]) => ({ [sense]: key }));
  $("#solve-status").textContent = "solving…";
  const started = performance.now();
  try {
    const { answer, figure } = await api("/api/solve", { ...designBody(), free, require, objectives });
    $("#solve-error").hidden = true;
    showSolution(answer);
    plot("fig-front", figure);
    $("#solve-status").textContent = `solved in ${((performance.now() - started) / 1000).toFixed(1)} s`;
  } catch (error) {
    $("#solve-error").hidden = false;
    $("#solve-error").textContent = "⚠ " + error.message;
    $("#solve-status").textContent = "";
  }
}

function showSolution(answer) {
  const out = $("#solve-result");
  out.replaceChildren();
  const verdict = document.createElement("div");
  verdict.className = `verdict ${answer.feasible ? "ok" : "no"}`;
  verdict.textContent = answer.feasible ? "feasible" : "infeasible within the bounds";
  out.append(verdict);
  if (!answer.feasible) {
    for (const entry of answer.unmet) {
      const line = document.createElement("div");
      const best = "best" in entry ? `best ${entry.best.toPrecision(4)}` : `best probability ${entry.best_probability.toFixed(3)}`;
      line.textContent = `cannot be met even at the bounds: ${entry.requirement} (${best})`;
      out.append(line);
    }
    for (const group of answer.conflicting) {
      const line = document.createElement("div");
      line.textContent = `cannot be met together: ${group.join("; ")}`;
      out.append(line);
    }
    return;
  }
  const points = answer.front || [answer];
  const keys = Object.keys(points[0].solution);
  const table = document.createElement("table");
  const head = table.createTHead().insertRow();
  for (const text of [...keys, "active requirements", "minimal", ""]) { const th = document.createElement("th"); th.textContent = text; head.append(th); }
  const body = table.createTBody();
  for (const point of points) {
    const tr = body.insertRow();
    for (const key of keys) cell(tr, Number(point.solution[key].toPrecision(6)).toString(), "num");
    cell(tr, point.active.join("; ") || "none");
    cell(tr, point.minimal ? "yes" : "no");
    const apply = document.createElement("button");
    apply.className = "small apply";
    apply.textContent = "use";
    apply.title = "set these values in the design";
    apply.addEventListener("click", () => {
      for (const key of keys) inputFor(key).value = String(Number(point.solution[key].toPrecision(6)));
      syncPresets(); syncSliders(); schedule();
    });
    tr.insertCell().append(apply);
  }
  out.append(table);
}

// ---- start ------------------------------------------------------------------------------------------------------
async function start() {
  SCHEMA = await api("/api/schema");
  fillPresets();
  fillKeySelects();
  setTexts(designFromUrl() || (await api("/api/config")).text);
  rangeFor($("#sweep-key-1"), $("#sweep-range-1"));
  addFree("light.luminous_flux_lm", "1000", "200000");
  addFree("lens.f_number", "1.4", "22");
  addRequirement("snr_db", ">=", "30");
  addRequirement("mean_fraction", "<=", "0.6");

  $("#design").addEventListener("input", (event) => {
    if (event.target.classList.contains("slider")) { onSlide(event.target); return; }
    if (event.target.classList.contains("value")) { syncPresets(); schedule(event.target.tagName === "SELECT" ? 0 : 250); }
  });
  $("#design").addEventListener("change", (event) => {
    if (event.target.classList.contains("preset")) applyPreset(event.target);
    else if (event.target.classList.contains("slider") || event.target.classList.contains("value")) syncSliders();
  });
  $("#design").addEventListener("keydown", (event) => {
    if (event.key === "Enter" && event.target.classList.contains("value")) { syncSliders(); schedule(); }
  });
  $("#save").addEventListener("click", save);
  $("#load-file").addEventListener("change", (event) => { if (event.target.files[0]) load(event.target.files[0]); event.target.value = ""; });
  $("#share").addEventListener("click", share);
  $("#share-close").addEventListener("click", () => { $("#share-box").hidden = true; });
  $("#reset").addEventListener("click", reset);
  $("#profile-add").addEventListener("click", addProfile);
  $("#sweep-key-1").addEventListener("change", () => rangeFor($("#sweep-key-1"), $("#sweep-range-1")));
  $("#sweep-key-2").addEventListener("change", () => rangeFor($("#sweep-key-2"), $("#sweep-range-2")));
  $("#sweep-run").addEventListener("click", runSweep);
  $("#solve-add-free").addEventListener("click", () => addFree());
  $("#solve-add-require").addEventListener("click", () => addRequirement());
  $("#solve-run").addEventListener("click", runSolve);
  await update();
}

start().catch((error) => { showError(error); setStatus("error"); });

// The rig console's page (docs/console.md): the live image and its statistics from the Server-Sent Events of
// /api/stream, the camera's, lights' and runs' controls through the JSON API. No build step.
"use strict";

const $ = (id) => document.getElementById(id);
const xsrfToken = () => (document.cookie.match(/(?:^|;\s*)_xsrf=([^;]*)/) || [])[1] || "";
const fmt = (v, digits = 4) => (v === null || v === undefined ? "–" : Number(v).toPrecision(digits));
const plotConfig = { displaylogo: false, responsive: true };
const state = { frameWidth: 1, frameHeight: 1, roi: null, trace: [], run: null, loading: false, pending: null,
  prediction: null, predictionFor: null };

async function api(path, body) {
  const options = body === undefined ? {} : {
    method: "POST", headers: { "Content-Type": "application/json", "X-XSRF-Token": xsrfToken() },
    body: JSON.stringify(body),
  };
  const response = await fetch(path, options);
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

function showError(id, error) { $(id).textContent = error ? String(error.message || error) : ""; }

// -- the live image -------------------------------------------------------------------------------------------
function imageUrl(frameId) {
  const clip = $("show-clip").checked ? 1 : 0, peaking = $("show-peaking").checked ? 1 : 0;
  return `/api/camera/frame.png?clip=${clip}&peaking=${peaking}&n=${frameId}`;
}

async function loadImage(frameId) {
  // One image request at a time; a newer frame waits for the one loading (the latest wins). The PNG is drawn on a
  // canvas once decoded, so the page never shows a half-loaded image.
  if (state.loading) { state.pending = frameId; return; }
  state.loading = true;
  try {
    const response = await fetch(imageUrl(frameId));
    if (response.ok) {
      const bitmap = await createImageBitmap(await response.blob());
      const canvas = $("live");
      if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
        canvas.width = bitmap.width; canvas.height = bitmap.height;
      }
      canvas.getContext("2d").drawImage(bitmap, 0, 0);
      canvas.dataset.frameId = response.headers.get("x-frame-id");
      bitmap.close();
      drawRoi();
    }
  } catch (error) { $("status").textContent = String(error.message || error); }
  state.loading = false;
  if (state.pending !== null) { const next = state.pending; state.pending = null; loadImage(next); }
}

function drawRoi() {
  const img = $("live"), box = $("roi-box"), roi = state.roi;
  if (!roi || !img.clientWidth) return;
  const sx = img.clientWidth / state.frameWidth, sy = img.clientHeight / state.frameHeight;
  Object.assign(box.style, {
    left: `${roi[0] * sx}px`, top: `${roi[1] * sy}px`, width: `${roi[2] * sx}px`, height: `${roi[3] * sy}px`,
  });
}

function showStats(s) {
  state.frameWidth = s.width; state.frameHeight = s.height;
  if (!state.dragging) state.roi = [s.roi.x, s.roi.y, s.roi.w, s.roi.h];
  $("s-frame").textContent = `#${s.frame_id} ${s.width}×${s.height} ${s.pixel_format}, ${s.exposure_us} µs, ${s.gain_db} dB`;
  $("s-mean").textContent = `${fmt(s.mean_dn, 5)} DN`;
  $("s-sat").textContent = `${fmt(100 * s.saturated_fraction, 3)} % (clip ${s.clip_level_dn} DN, ${s.clip_source})`;
  $("s-roi-mean").textContent = `${fmt(s.roi.mean_dn, 5)} DN`;
  $("s-roi-var").textContent = `${fmt(s.roi.variance_dn2, 5)} DN²`;
  $("s-roi-snr").textContent = fmt(s.roi.snr, 4);
  $("s-roi").textContent = `${s.roi.x}, ${s.roi.y}, ${s.roi.w}, ${s.roi.h}`;
  $("fps").textContent = `${fmt(s.fps, 3)} frames/s`;
  $("f-now").textContent = fmt(s.sharpness, 4);
  $("f-best").textContent = fmt(s.sharpness_best, 4);
  $("f-lap").textContent = fmt(s.sharpness_laplacian, 4);
  $("f-lap-best").textContent = fmt(s.sharpness_laplacian_best, 4);
  loadImage(s.frame_id);
  drawRoi();
  const counts = s.histogram.counts, width = s.histogram.max_dn / s.histogram.bins_dn;
  const colours = { mono: "#444", R: "#d62728", G: "#2ca02c", B: "#1f77b4" };
  Plotly.react("histogram", Object.entries(counts).map(([name, c]) => ({
    x: c.map((_, i) => (i + 0.5) * width), y: c, name, type: "bar", width, opacity: 0.7,
    marker: { color: colours[name], line: { width: 0 } },
  })), {
    barmode: "overlay", bargap: 0,
    margin: { l: 50, r: 10, t: 10, b: 35 }, height: 180, showlegend: Object.keys(counts).length > 1,
    xaxis: { title: { text: "DN" }, range: [0, s.histogram.max_dn] },
    yaxis: { type: "log", title: { text: "pixels" } },
    shapes: [{ type: "line", x0: s.clip_level_dn, x1: s.clip_level_dn, y0: 0, y1: 1, yref: "paper",
      line: { color: "red", dash: "dot" } }],
  }, plotConfig);
  state.trace.push([new Date(s.t_grab_s * 1000), s.sharpness]);
  if (state.trace.length > 600) state.trace.shift();
  if (s.frame_id % 3 === 0) drawTrace(s.sharpness_best);
}

function drawTrace(best) {
  Plotly.react("focus-trace", [
    { x: state.trace.map((t) => t[0]), y: state.trace.map((t) => t[1]), name: "sharpness", mode: "lines" },
    { x: [state.trace[0][0], state.trace[state.trace.length - 1][0]], y: [best, best], name: "best",
      mode: "lines", line: { dash: "dot", color: "#2ca02c" } },
  ], { margin: { l: 50, r: 10, t: 10, b: 30 }, height: 170, showlegend: false,
    yaxis: { title: { text: "Tenengrad/mean²" } } }, plotConfig);
}

// -- the ROI: drag it over the image --------------------------------------------------------------------------
function setupRoi() {
  const img = $("live");
  let start = null;
  const toFrame = (event) => {
    const rect = img.getBoundingClientRect();
    return [Math.round((event.clientX - rect.left) / rect.width * state.frameWidth),
      Math.round((event.clientY - rect.top) / rect.height * state.frameHeight)];
  };
  const down = (event) => {
    if (!state.roi) return;
    event.preventDefault();
    start = { at: toFrame(event), roi: state.roi.slice(), draw: event.shiftKey };
    state.dragging = true;
  };
  img.addEventListener("mousedown", down);
  $("roi-box").addEventListener("mousedown", down);
  window.addEventListener("mousemove", (event) => {
    if (!start) return;
    const [x, y] = toFrame(event), clamp = (v, hi) => Math.max(0, Math.min(v, hi));
    if (start.draw) {
      const x0 = clamp(Math.min(x, start.at[0]), state.frameWidth - 1), y0 = clamp(Math.min(y, start.at[1]), state.frameHeight - 1);
      state.roi = [x0, y0, Math.max(3, clamp(Math.abs(x - start.at[0]), state.frameWidth - x0)),
        Math.max(3, clamp(Math.abs(y - start.at[1]), state.frameHeight - y0))];
    } else {
      const r = start.roi;
      state.roi = [clamp(r[0] + x - start.at[0], state.frameWidth - r[2]), clamp(r[1] + y - start.at[1], state.frameHeight - r[3]), r[2], r[3]];
    }
    drawRoi();
  });
  window.addEventListener("mouseup", async () => {
    if (!start) return;
    start = null;
    try { await api("/api/view", { roi: state.roi }); state.trace = []; showError("camera-error"); }
    catch (error) { showError("camera-error", error); }
    state.dragging = false;
  });
  window.addEventListener("resize", drawRoi);
}

// -- the rig: camera read-back, lights, spectrometer, control --------------------------------------------------
function showCamera(camera) {
  if (!camera) return;
  $("camera-model").textContent = `${camera.vendor} ${camera.model} (${camera.backend})`;
  $("readback").textContent = `${camera.exposure_us} µs, ${camera.gain_db} dB, ${camera.pixel_format}, ` +
    `${camera.width}×${camera.height} at (${camera.offset_x}, ${camera.offset_y})`;
  const select = $("pixel_format");
  if (!select.options.length) {
    for (const name of camera.pixel_formats) select.add(new Option(name, name));
  }
  for (const key of ["exposure_us", "gain_db"]) {
    if (document.activeElement !== $(key)) $(key).value = camera[key];
  }
  select.value = camera.pixel_format;
  if (document.activeElement !== $("camera_roi")) {
    $("camera_roi").value = [camera.offset_x, camera.offset_y, camera.width, camera.height].join(",");
  }
}

function showControl(control) {
  $("control").textContent = control.controlling ? "controlling the rig" : "watching (read-only)";
  $("control").className = `status ${control.controlling ? "ok" : "watch"}`;
  $("take-control").hidden = control.controlling || !control.free;
  document.body.classList.toggle("watcher", !control.controlling);
}

function showLights(lights) {
  // Rows are made once and then updated in place: a field being edited keeps what the user typed.
  const box = $("lights");
  for (const [name, light] of Object.entries(lights)) {
    let row = box.querySelector(`.light[data-name="${CSS.escape(name)}"]`);
    if (!row) {
      row = document.createElement("div");
      row.className = "light";
      row.dataset.name = name;
      row.innerHTML = `<strong></strong> <label><input type="checkbox" class="light-on"> on</label>
        <label>level <input type="number" class="light-level" min="0" max="1" step="0.05"></label>
        <button class="light-apply">Set</button> <span class="readback"></span>`;
      row.querySelector("strong").textContent = name;
      row.querySelector(".light-apply").addEventListener("click", async () => {
        try {
          await api(`/api/lights/${encodeURIComponent(name)}`, {
            on: row.querySelector(".light-on").checked, level: Number(row.querySelector(".light-level").value),
          });
          showError("camera-error");
          refreshRig();
        } catch (error) { showError("camera-error", error); }
      });
      row.querySelector(".light-on").checked = light.on;
      row.querySelector(".light-level").value = light.level;
      box.appendChild(row);
    }
    const currents = Object.entries(light).filter(([k]) => k.endsWith("_a"))
      .map(([k, v]) => `${k} ${fmt(v, 4)}`).join(", ");
    row.querySelector(".readback").textContent =
      `read back: ${light.on ? "on" : "off"}, level ${fmt(light.level, 3)}${currents ? ", " + currents : ""}; safe state: off`;
  }
}

async function refreshRig() {
  try {
    const rig = await api("/api/rig");
    showControl(rig.control);
    if (rig.held_by_run) { $("status").textContent = "a run holds the rig"; return; }
    $("status").textContent = "";
    showCamera(rig.camera);
    showLights(rig.lights);
    if (rig.spectrometer) refreshSpectrum();
  } catch (error) { $("status").textContent = String(error.message || error); }
}

async function refreshSpectrum() {
  try {
    const s = await api("/api/spectrometer");
    $("spectrum-readout").textContent = `${s.model}: ${fmt(s.irradiance_w_m2, 4)} W/m², ` +
      `${s.saturated ? "SATURATED" : "not saturated"}, ${s.integration_ms} ms × ${s.averaging}`;
    Plotly.react("spectrum", [{ x: s.wavelength_nm, y: s.irradiance_w_m2_nm, mode: "lines" }], {
      margin: { l: 55, r: 10, t: 10, b: 35 }, height: 170,
      xaxis: { title: { text: "nm" } }, yaxis: { title: { text: "W/m²/nm" } },
    }, plotConfig);
  } catch (error) { $("spectrum-readout").textContent = String(error.message || error); }
}

async function refreshFocusModel() {
  try {
    const f = await api("/api/focus");
    const m = f.model, lens = m.close_up_lens_dpt ? `, with a +${fmt(m.close_up_lens_dpt, 3)} dpt close-up lens` : "";
    $("focus-model").textContent = `Model (uwlab port trace): the ${m.port} port shows the target at ` +
      `${fmt(m.target_distance_m, 3)} m as an image ${fmt(m.image_distance_m, 4)} m from the pupil; ` +
      `set the lens to ${fmt(m.setting_m, 4)} m${lens}. Depth of field ${fmt(m.dof_m.near, 4)}–${fmt(m.dof_m.far, 4)} m.`;
  } catch (error) { $("focus-model").textContent = String(error.message || error); }
}

// -- runs -----------------------------------------------------------------------------------------------------
function showRun(run) {
  state.run = run;
  const active = run.state === "running" || run.state === "paused";
  $("run-pause").disabled = run.state !== "running";
  $("run-resume").disabled = run.state !== "paused";
  $("run-abort").disabled = !active;
  $("run-start").disabled = active;
  const eta = run.eta_s === null ? "" : `, ${fmt(run.eta_s, 3)} s left`;
  const recoveries = Object.entries(run.recoveries).filter(([, n]) => n).map(([k, n]) => `${k} ${n}`).join(", ");
  $("run-status").textContent = `run ${run.id}: ${run.state}, ${run.points_done}/${run.points_total} points${eta}` +
    ` → ${run.out}` + (recoveries ? `; recoveries: ${recoveries}` : "") +
    (run.state === "paused" ? "; lights in their safe state (off)" : "") +
    (run.faults.length ? `; faults: ${run.faults.join("; ")}` : "");
  $("run-status").dataset.state = run.state;
  if (state.predictionFor !== run.id) loadPrediction(run.id);
  drawRun();
}

// The model's predicted band of the run's plan (GET /api/runs/ID/prediction), fetched once per run.
async function loadPrediction(runId) {
  state.predictionFor = runId;
  state.prediction = null;
  try { state.prediction = await api(`/api/runs/${runId}/prediction`); }
  catch (error) { state.prediction = { configurations: [], error: String(error.message || error) }; }
  if (state.run && state.run.id === runId) drawRun();
}

const SWEEP_COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
const translucent = (hex) => `rgba(${[1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16)).join(",")},0.18)`;

function drawRun() {
  // Per configuration (sweep): the predicted band (shaded, 2.5–97.5 %) and its median (dashed) under the points.
  const run = state.run, prediction = state.prediction || { configurations: [] };
  const bySweep = {};
  for (const c of prediction.configurations) bySweep[c.sweep_id] = [];
  for (const p of run.points) (bySweep[p.sweep_id] = bySweep[p.sweep_id] || []).push(p);
  const ids = Object.keys(bySweep), colour = (id) => SWEEP_COLOURS[ids.indexOf(id) % SWEEP_COLOURS.length];
  const source = prediction.source || "";
  const [lo, hi] = prediction.band_percent || [2.5, 97.5];
  const bands = prediction.configurations.flatMap((c) => [
    { x: c.exposure_us, y: c.lo, mode: "lines", line: { width: 0, color: colour(c.sweep_id) }, hoverinfo: "skip",
      showlegend: false, legendgroup: c.sweep_id, meta: "band-lo" },
    { x: c.exposure_us, y: c.hi, mode: "lines", line: { width: 0, color: colour(c.sweep_id) }, fill: "tonexty",
      fillcolor: translucent(colour(c.sweep_id)), legendgroup: c.sweep_id, meta: "band",
      name: `${c.sweep_id}: ${lo}–${hi} % band (${source})` },
    { x: c.exposure_us, y: c.median, mode: "lines", line: { dash: "dash", width: 1.5, color: colour(c.sweep_id) },
      legendgroup: c.sweep_id, meta: "median", name: `${c.sweep_id}: predicted median (${source})` },
  ]);
  const points = Object.entries(bySweep).filter(([, pts]) => pts.length).map(([id, pts]) => ({
    x: pts.map((p) => p.exposure_us), y: pts.map((p) => p.signal_dn), name: id, mode: "lines+markers",
    legendgroup: id, line: { color: colour(id) }, meta: "points",
    marker: { color: colour(id), symbol: pts.map((p) => (p.saturated ? "x" : "circle")) },
  }));
  const skipped = Object.entries(prediction.skipped || {}).map(([id, why]) => `${id}: ${why}`).join("; ");
  $("run-prediction").textContent = prediction.error ? `no predicted band: ${prediction.error}` :
    prediction.configurations.length ? `predicted from ${source} (${prediction.model} chain, ${prediction.samples} ` +
      `draws): median and ${lo}–${hi} % band of a new measurement` + (skipped ? `; not predicted: ${skipped}` : "") :
    (skipped ? `not predicted: ${skipped}` : "");
  Plotly.react("run-points", [...bands, ...points], { margin: { l: 60, r: 10, t: 30, b: 40 }, height: 320,
    xaxis: { type: "log", title: { text: "exposure [µs]" } }, yaxis: { title: { text: "signal [DN]" } },
    legend: { font: { size: 11 } } }, plotConfig);
}

async function runAction(action) {
  try { showRun(await api(`/api/runs/${state.run.id}/${action}`, {})); showError("run-error"); }
  catch (error) { showError("run-error", error); }
}

// -- wiring ---------------------------------------------------------------------------------------------------
function connect() {
  const events = new EventSource("/api/stream");
  events.addEventListener("stats", (e) => showStats(JSON.parse(e.data)));
  events.addEventListener("rig", (e) => {
    const rig = JSON.parse(e.data);
    state.trace = [];  // the server starts the sharpness trace over at every change of a setting
    if (rig.error) $("status").textContent = rig.error;
    refreshRig();
  });
  events.addEventListener("run", (e) => showRun(JSON.parse(e.data)));
  events.onerror = () => { $("status").textContent = "reconnecting…"; };
  events.onopen = () => { $("status").textContent = ""; };
}

document.addEventListener("DOMContentLoaded", () => {
  setupRoi();
  $("apply-camera").addEventListener("click", async () => {
    const body = { exposure_us: Number($("exposure_us").value), gain_db: Number($("gain_db").value),
      pixel_format: $("pixel_format").value };
    const roi = $("camera_roi").value.trim();
    if (roi) body.roi = roi;
    try { showCamera(await api("/api/camera", body)); showError("camera-error"); }
    catch (error) { showError("camera-error", error); }
  });
  $("focus-reset").addEventListener("click", async () => {
    try { await api("/api/focus/reset", {}); state.trace = []; } catch (error) { showError("camera-error", error); }
  });
  $("take-control").addEventListener("click", async () => {
    try { showControl(await api("/api/control", {})); } catch (error) { $("status").textContent = error.message; }
  });
  $("run-start").addEventListener("click", async () => {
    try {
      const started = await api("/api/runs", { plan: $("run-plan").value, out: $("run-out").value || null,
        fit: $("run-fit").value.trim() || null });
      showRun(await api(`/api/runs/${started.id}`));
      showError("run-error");
    } catch (error) { showError("run-error", error); }
  });
  for (const action of ["pause", "resume", "abort"]) $(`run-${action}`).addEventListener("click", () => runAction(action));
  for (const id of ["show-clip", "show-peaking"]) $(id).addEventListener("change", () => loadImage(Number($("live").dataset.frameId || 0)));
  refreshRig();
  refreshFocusModel();
  connect();
});

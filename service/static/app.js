// i2v-loc yard dashboard: plain JS, no build step, no external resources.
"use strict";

const API = "/api/v1";
const PLOT_WINDOW_S = 60;
const COLORS = { truck: "#ffb020", trailer: "#3fd18b", points: "rgba(170,180,190,0.75)", sensor: "#4fa3ff",
                 grid: "#1d242c", axis: "#34404c", text: "#e4e7eb", muted: "#8a939e", bad: "#ff5f56", warn: "#ffcc00" };
const PLOT_COLORS = ["#4fa3ff", "#ffb020", "#3fd18b", "#ff5fa2", "#b48cff", "#ffe066"];
const UNCONFIRMED_COLOR = "#6b737c";
// A vehicle is shown once seen whole (truck and trailer) in this many states in a row, and stays
// shown while it is reported: a short-lived or half-seen track (a phantom) is not.
const CONFIRM_STATES = 5;

const ui = {
  yard: document.getElementById("yard"),
  plot: document.getElementById("hitch-plot"),
  vehicles: document.getElementById("vehicles"),
  sensors: document.querySelector("#sensors tbody"),
  conn: document.getElementById("conn-status"),
  frameInfo: document.getElementById("frame-info"),
  fpsInfo: document.getElementById("fps-info"),
  paramsInfo: document.getElementById("params-info"),
  token: document.getElementById("token"),
  editor: document.getElementById("param-editor"),
  apply: document.getElementById("apply-params"),
  reset: document.getElementById("reset-params"),
  paramStatus: document.getElementById("param-status"),
  paramErrors: document.getElementById("param-errors"),
  showUnconfirmed: document.getElementById("show-unconfirmed"),
};

const store = {
  state: null,          // latest state message
  points: [],           // flat [x0, y0, x1, y1, ...] of foreground points
  sensors: [],          // from /sensors (positions, status)
  params: null,         // parameters in force
  version: null,
  schema: null,
  hitch: new Map(),     // vehicle id -> [[stamp_s, hitch_deg], ...] of confirmed vehicles
  streak: new Map(),    // vehicle id -> states in a row in which it was seen whole
  confirmed: new Set(), // ids of the confirmed vehicles
  arrivals: [],         // wall-clock times of the last states, for the frame rate
};

// ------------------------------------------------------------------ HTTP and token

ui.token.value = sessionStorage.getItem("i2v-loc-token") || "";
ui.token.addEventListener("change", () => sessionStorage.setItem("i2v-loc-token", ui.token.value.trim()));

function authHeaders() {
  const token = ui.token.value.trim();
  return token ? { Authorization: "Bearer " + token } : {};
}

async function getJSON(path) {
  const response = await fetch(API + path, { headers: authHeaders() });
  if (!response.ok) throw new Error(`${path}: HTTP ${response.status}`);
  return response.json();
}

// ------------------------------------------------------------------ WebSocket

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${scheme}://${location.host}/ws/states?points=true`);
  ws.onopen = () => {
    const token = ui.token.value.trim();
    if (token) ws.send(JSON.stringify({ token }));
    setConnection(true, "live");
  };
  ws.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "state") onState(message);
    else if (message.type === "params") onParams(message);
    else if (message.type === "error") setConnection(false, message.detail);
  };
  ws.onclose = () => { setConnection(false, "disconnected, retrying…"); setTimeout(connect, 1000); };
}

function setConnection(on, text) {
  ui.conn.textContent = text;
  ui.conn.className = "badge " + (on ? "on" : "off");
}

function onState(state) {
  store.state = state;
  if (state.foreground && Array.isArray(state.foreground.xy)) store.points = state.foreground.xy;
  const now = performance.now() / 1000;
  store.arrivals.push(now);
  while (store.arrivals.length > 20) store.arrivals.shift();
  updateConfirmed(state.vehicles || []);
  for (const v of state.vehicles || []) {
    if (typeof v.hitch_deg !== "number" || !store.confirmed.has(v.id)) continue;
    if (!store.hitch.has(v.id)) store.hitch.set(v.id, []);
    store.hitch.get(v.id).push([state.stamp_s, v.hitch_deg]);
  }
  for (const [id, series] of store.hitch) {
    while (series.length && series[0][0] < state.stamp_s - PLOT_WINDOW_S) series.shift();
    if (!series.length) store.hitch.delete(id);
  }
  scheduleDraw();
}

function updateConfirmed(vehicles) {
  const streak = new Map();
  for (const v of vehicles) streak.set(v.id, v.truck && v.trailer ? (store.streak.get(v.id) || 0) + 1 : 0);
  store.streak = streak;
  for (const id of store.confirmed) if (!streak.has(id)) store.confirmed.delete(id);
  for (const [id, n] of streak) if (n >= CONFIRM_STATES) store.confirmed.add(id);
}

function shownVehicles() {
  const all = (store.state && store.state.vehicles) || [];
  return all.filter((v) => store.confirmed.has(v.id) || ui.showUnconfirmed.checked);
}

ui.showUnconfirmed.addEventListener("change", () => scheduleDraw());

function onParams(message) {
  store.version = message.version;
  store.params = message.params;
  ui.paramsInfo.textContent = `params v${message.version}`;
  if (!ui.editor.querySelector(".dirty")) renderEditor();
}

// ------------------------------------------------------------------ drawing

let drawPending = false;
function scheduleDraw() {
  if (drawPending) return;
  drawPending = true;
  requestAnimationFrame(() => { drawPending = false; drawAll(); });
}

function drawAll() {
  const s = store.state;
  if (s) {
    ui.frameInfo.textContent = `frame ${s.frame} · t ${Number(s.stamp_s).toFixed(1)} s`;
    const a = store.arrivals;
    const fps = a.length > 1 ? (a.length - 1) / (a[a.length - 1] - a[0]) : 0;
    ui.fpsInfo.textContent = `${fps.toFixed(1)} fps · ${s.latency_ms && s.latency_ms.total != null ? s.latency_ms.total.toFixed(1) : "–"} ms`;
  }
  drawYard();
  drawVehicleList();
  drawHitchPlot();
}

function worldBounds() {
  const r = store.params && store.params.region;
  let b = r ? { x0: r.x_min_m, x1: r.x_max_m, y0: r.y_min_m, y1: r.y_max_m } : { x0: -40, x1: 40, y0: -25, y1: 40 };
  for (const s of store.sensors) {
    if (!s.position) continue;
    b.x0 = Math.min(b.x0, s.position.x_m - 3); b.x1 = Math.max(b.x1, s.position.x_m + 3);
    b.y0 = Math.min(b.y0, s.position.y_m - 3); b.y1 = Math.max(b.y1, s.position.y_m + 3);
  }
  return b;
}

function viewTransform(canvas) {
  const b = worldBounds();
  const margin = 20;
  const scale = Math.min((canvas.width - 2 * margin) / (b.x1 - b.x0), (canvas.height - 2 * margin) / (b.y1 - b.y0));
  const ox = (canvas.width - scale * (b.x1 - b.x0)) / 2, oy = (canvas.height - scale * (b.y1 - b.y0)) / 2;
  return { b, scale, px: (x) => ox + (x - b.x0) * scale, py: (y) => canvas.height - oy - (y - b.y0) * scale };
}

function drawYard() {
  const canvas = ui.yard, ctx = canvas.getContext("2d");
  const t = viewTransform(canvas);
  ctx.fillStyle = "#0b0e11";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  drawGrid(ctx, t);
  ctx.fillStyle = COLORS.points;
  const p = store.points;
  for (let i = 0; i + 1 < p.length; i += 2) ctx.fillRect(t.px(p[i]) - 1, t.py(p[i + 1]) - 1, 2, 2);
  for (const sensor of store.sensors) drawSensor(ctx, t, sensor);
  const state = store.state;
  if (!state) return;
  for (const c of state.clusters || []) {
    if (!c.center) continue;
    ctx.strokeStyle = c.status && c.status.startsWith("vehicle") ? COLORS.text : COLORS.muted;
    ctx.beginPath(); ctx.arc(t.px(c.center[0]), t.py(c.center[1]), 3, 0, 2 * Math.PI); ctx.stroke();
  }
  for (const v of shownVehicles()) drawVehicle(ctx, t, v);
}

function drawGrid(ctx, t) {
  ctx.lineWidth = 1;
  const step = 10;
  for (let x = Math.ceil(t.b.x0 / step) * step; x <= t.b.x1; x += step) {
    ctx.strokeStyle = x === 0 ? COLORS.axis : COLORS.grid;
    ctx.beginPath(); ctx.moveTo(t.px(x), t.py(t.b.y0)); ctx.lineTo(t.px(x), t.py(t.b.y1)); ctx.stroke();
  }
  for (let y = Math.ceil(t.b.y0 / step) * step; y <= t.b.y1; y += step) {
    ctx.strokeStyle = y === 0 ? COLORS.axis : COLORS.grid;
    ctx.beginPath(); ctx.moveTo(t.px(t.b.x0), t.py(y)); ctx.lineTo(t.px(t.b.x1), t.py(y)); ctx.stroke();
  }
}

function drawSensor(ctx, t, sensor) {
  if (!sensor.position) return;
  const x = t.px(sensor.position.x_m), y = t.py(sensor.position.y_m);
  const yaw = (sensor.position.yaw_deg * Math.PI) / 180;
  ctx.save();
  ctx.translate(x, y); ctx.rotate(-yaw);
  ctx.fillStyle = statusClass(sensor.status) === "st-ok" ? COLORS.sensor : statusClass(sensor.status) === "st-warn" ? COLORS.warn : COLORS.bad;
  ctx.beginPath(); ctx.moveTo(9, 0); ctx.lineTo(-6, 6); ctx.lineTo(-6, -6); ctx.closePath(); ctx.fill();
  ctx.restore();
  ctx.fillStyle = COLORS.text; ctx.font = "12px system-ui";
  ctx.fillText(sensor.name, x + 8, y - 8);
}

function drawUnit(ctx, t, unit, color) {
  if (!unit || !unit.center || !unit.dimensions || typeof unit.yaw_deg !== "number") return null;
  const [l, w] = unit.dimensions;
  const yaw = (unit.yaw_deg * Math.PI) / 180;
  const cx = t.px(unit.center[0]), cy = t.py(unit.center[1]);
  ctx.save();
  ctx.translate(cx, cy); ctx.rotate(-yaw);
  ctx.fillStyle = color + "40"; ctx.strokeStyle = color; ctx.lineWidth = 2;
  ctx.fillRect((-l / 2) * t.scale, (-w / 2) * t.scale, l * t.scale, w * t.scale);
  ctx.strokeRect((-l / 2) * t.scale, (-w / 2) * t.scale, l * t.scale, w * t.scale);
  // heading: an arrow from the centre to the front face
  ctx.beginPath(); ctx.moveTo(0, 0); ctx.lineTo((l / 2) * t.scale + 8, 0); ctx.stroke();
  ctx.beginPath(); ctx.moveTo((l / 2) * t.scale + 8, 0); ctx.lineTo((l / 2) * t.scale + 2, -4);
  ctx.lineTo((l / 2) * t.scale + 2, 4); ctx.closePath(); ctx.fillStyle = color; ctx.fill();
  ctx.restore();
  return [cx, cy];
}

function drawVehicle(ctx, t, v) {
  const confirmed = store.confirmed.has(v.id);
  const trailerAt = drawUnit(ctx, t, v.trailer, confirmed ? COLORS.trailer : UNCONFIRMED_COLOR);
  const truckAt = drawUnit(ctx, t, v.truck, confirmed ? COLORS.truck : UNCONFIRMED_COLOR);
  const at = truckAt || trailerAt;
  if (!at) return;
  ctx.fillStyle = confirmed ? COLORS.text : UNCONFIRMED_COLOR; ctx.font = "bold 13px system-ui";
  ctx.fillText(`#${v.id} ${v.vehicle || ""}  ${formatHitch(v.hitch_deg)}`, at[0] + 12, at[1] - 12);
}

function formatHitch(deg) {
  return typeof deg === "number" ? `${deg >= 0 ? "+" : ""}${deg.toFixed(1)}°` : "–";
}

function drawVehicleList() {
  const vehicles = shownVehicles();
  if (!vehicles.length) { ui.vehicles.innerHTML = '<p class="muted">no vehicle</p>'; return; }
  ui.vehicles.replaceChildren(...vehicles.map((v) => {
    const row = document.createElement("div");
    row.className = store.confirmed.has(v.id) ? "vehicle" : "vehicle unconfirmed"; row.dataset.id = v.id;
    if (!store.confirmed.has(v.id)) row.title = "not confirmed: not yet seen whole in " + CONFIRM_STATES + " states in a row";
    const name = document.createElement("span");
    name.textContent = `#${v.id} ${v.vehicle || "?"}` + (v.truck && v.truck.yaw_deg != null ? ` · truck ${v.truck.yaw_deg.toFixed(1)}°` : "");
    const hitch = document.createElement("span");
    hitch.className = "hitch"; hitch.textContent = formatHitch(v.hitch_deg);
    hitch.title = "hitch angle = trailer yaw − truck yaw";
    row.append(name, hitch);
    return row;
  }));
}

function drawHitchPlot() {
  const canvas = ui.plot, ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, left = 36, bottom = 18;
  ctx.fillStyle = "#0b0e11"; ctx.fillRect(0, 0, W, H);
  const now = store.state ? store.state.stamp_s : 0;
  let maxAbs = 10;
  for (const series of store.hitch.values()) for (const [, h] of series) maxAbs = Math.max(maxAbs, Math.abs(h));
  maxAbs = Math.ceil(maxAbs / 10) * 10;
  const px = (s) => left + ((s - (now - PLOT_WINDOW_S)) / PLOT_WINDOW_S) * (W - left - 4);
  const py = (h) => (H - bottom) / 2 - (h / maxAbs) * ((H - bottom) / 2 - 6);
  ctx.strokeStyle = COLORS.grid; ctx.fillStyle = COLORS.muted; ctx.font = "11px system-ui";
  for (const h of [-maxAbs, 0, maxAbs]) {
    ctx.beginPath(); ctx.moveTo(left, py(h)); ctx.lineTo(W, py(h)); ctx.stroke();
    ctx.fillText(`${h}°`, 2, py(h) + 4);
  }
  for (let s = 0; s <= PLOT_WINDOW_S; s += 10) ctx.fillText(`${s - PLOT_WINDOW_S}s`, px(now - PLOT_WINDOW_S + s) - 10, H - 4);
  let i = 0;
  for (const [id, series] of store.hitch) {
    const color = PLOT_COLORS[i++ % PLOT_COLORS.length];
    ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath();
    series.forEach(([s, h], k) => (k ? ctx.lineTo(px(s), py(h)) : ctx.moveTo(px(s), py(h))));
    ctx.stroke();
    ctx.fillStyle = color; ctx.fillText(`#${id}`, W - 30, 12 * i);
  }
}

// ------------------------------------------------------------------ sensors

function statusClass(status) {
  if (status === "ok") return "st-ok";
  if (status === "waiting" || (status || "").startsWith("fault")) return "st-warn";
  return "st-bad";
}

async function refreshSensors() {
  try {
    store.sensors = (await getJSON("/sensors")).sensors;
  } catch (err) {
    return;
  }
  ui.sensors.replaceChildren(...store.sensors.map((s) => {
    const row = document.createElement("tr");
    const cells = [s.name, s.status, `${s.rate_hz.toFixed(1)} Hz`, String(s.drops),
                   s.last_stamp_s == null ? "–" : `${s.last_stamp_s.toFixed(2)} s`];
    cells.forEach((text, k) => {
      const td = document.createElement("td");
      td.textContent = text;
      if (k === 1) td.className = statusClass(s.status);
      row.append(td);
    });
    return row;
  }));
  scheduleDraw();
}

// ------------------------------------------------------------------ parameter editor (from the JSON Schema)

function resolve(node) {
  while (node && node.$ref) node = store.schema.$defs[node.$ref.split("/").pop()];
  return node || {};
}

function enumOf(node) {
  if (Array.isArray(node.enum)) return node.enum;
  const alternatives = node.anyOf || node.oneOf;
  if (alternatives && alternatives.every((a) => "const" in a)) return alternatives.map((a) => a.const);
  return null;
}

function rangeText(node) {
  const parts = [];
  if (node.minimum != null) parts.push(`≥ ${node.minimum}`);
  if (node.exclusiveMinimum != null) parts.push(`> ${node.exclusiveMinimum}`);
  if (node.maximum != null) parts.push(`≤ ${node.maximum}`);
  if (node.exclusiveMaximum != null) parts.push(`< ${node.exclusiveMaximum}`);
  return parts.join(", ");
}

function renderEditor() {
  if (!store.schema || !store.params) return;
  const open = new Set([...ui.editor.querySelectorAll("details[open]")].map((d) => d.dataset.path));
  ui.editor.replaceChildren(...Object.entries(store.schema.properties).map(([key, node]) =>
    renderNode(key, [key], resolve(node), store.params[key], open)));
}

function renderNode(label, path, node, value, open) {
  if (value !== null && typeof value === "object") {
    const details = document.createElement("details");
    details.dataset.path = path.join(".");
    if (open.has(details.dataset.path)) details.open = true;
    const summary = document.createElement("summary");
    summary.textContent = label + (value.name ? ` (${value.name})` : "");
    if (node.description) summary.title = node.description;
    details.append(summary);
    const entries = Array.isArray(value) ? value.map((v, i) => [i, v]) : Object.entries(value);
    for (const [k, v] of entries) {
      let child = {};
      if (Array.isArray(value)) child = resolve(node.items);
      else if (node.properties && node.properties[k]) child = resolve(node.properties[k]);
      else if (node.additionalProperties && typeof node.additionalProperties === "object") child = resolve(node.additionalProperties);
      details.append(renderNode(String(k), [...path, k], child, v, open));
    }
    return details;
  }
  return renderField(label, path, node, value);
}

function renderField(label, path, node, value) {
  const row = document.createElement("div");
  row.className = "field";
  const id = "p-" + path.join("-");
  const name = document.createElement("label");
  name.htmlFor = id; name.textContent = label; name.title = node.description || label;
  let input;
  const options = enumOf(node);
  if (options) {
    input = document.createElement("select");
    for (const option of options) {
      const o = document.createElement("option");
      o.value = JSON.stringify(option); o.textContent = String(option);
      input.append(o);
    }
    input.value = JSON.stringify(value);
  } else if (node.type === "boolean" || typeof value === "boolean") {
    input = document.createElement("input");
    input.type = "checkbox"; input.checked = Boolean(value);
  } else if (node.type === "number" || node.type === "integer" || typeof value === "number") {
    input = document.createElement("input");
    input.type = "text"; input.inputMode = "decimal"; input.value = String(value);
  } else {
    input = document.createElement("input");
    input.type = "text"; input.value = value == null ? "" : String(value);
  }
  input.id = id;
  input.dataset.path = path.join(".");
  input.dataset.kind = options ? "enum" : input.type === "checkbox" ? "bool" : (node.type === "number" || node.type === "integer" || typeof value === "number") ? "number" : "string";
  input.dataset.original = inputValue(input);
  input.addEventListener("input", () => input.classList.toggle("dirty", inputValue(input) !== input.dataset.original));
  input.addEventListener("change", () => input.classList.toggle("dirty", inputValue(input) !== input.dataset.original));
  row.append(name, input);
  const range = rangeText(node);
  if (range || node.description) {
    const hint = document.createElement("small");
    hint.textContent = [range, node.description].filter(Boolean).join(" · ");
    row.append(hint);
  }
  return row;
}

function inputValue(input) {
  return input.type === "checkbox" ? String(input.checked) : input.value;
}

function parsedValue(input) {
  const kind = input.dataset.kind;
  if (kind === "bool") return input.checked;
  if (kind === "enum") return JSON.parse(input.value);
  if (kind === "number") {
    const text = input.value.trim();
    const n = Number(text);
    return text !== "" && Number.isFinite(n) ? n : text; // the server explains what is wrong
  }
  return input.value;
}

function setAt(obj, path, value) {
  let node = obj;
  for (let i = 0; i < path.length - 1; i++) node = node[path[i]];
  node[path[path.length - 1]] = value;
}

// JSON merge patch from `before` to `after`: arrays (sensors) are replaced whole.
function mergeDiff(before, after) {
  const patch = {};
  for (const key of Object.keys(after)) {
    const a = before[key], b = after[key];
    if (b && typeof b === "object" && !Array.isArray(b) && a && typeof a === "object" && !Array.isArray(a)) {
      const sub = mergeDiff(a, b);
      if (Object.keys(sub).length) patch[key] = sub;
    } else if (JSON.stringify(a) !== JSON.stringify(b)) {
      patch[key] = b;
    }
  }
  return patch;
}

function editedPatch() {
  const edited = JSON.parse(JSON.stringify(store.params));
  for (const input of ui.editor.querySelectorAll("[data-path].dirty")) {
    const path = input.dataset.path.split(".").map((p) => (/^\d+$/.test(p) ? Number(p) : p));
    setAt(edited, path, parsedValue(input));
  }
  return mergeDiff(store.params, edited);
}

function showParamStatus(text, ok) {
  ui.paramStatus.textContent = text;
  ui.paramStatus.className = ok ? "ok" : "bad";
}

async function applyParams() {
  ui.paramErrors.replaceChildren();
  ui.editor.querySelectorAll(".invalid").forEach((el) => el.classList.remove("invalid"));
  const patch = editedPatch();
  if (!Object.keys(patch).length) { showParamStatus("nothing changed", true); return; }
  let response, body;
  try {
    response = await fetch(API + "/params", {
      method: "PATCH",
      headers: { "Content-Type": "application/merge-patch+json", ...authHeaders() },
      body: JSON.stringify(patch),
    });
    body = await response.json().catch(() => ({}));
  } catch (err) {
    showParamStatus(`request failed: ${err}`, false);
    return;
  }
  if (response.ok || body.in_force === true) {  // 507: in force, but the parameter file is behind
    store.params = body.params; store.version = body.version;
    ui.paramsInfo.textContent = `params v${body.version}`;
    renderEditor();
    if (response.ok) showParamStatus(`applied: version ${body.version}`, true);
    else showParamStatus(`applied: version ${body.version}, but NOT saved: ${body.detail}`, false);
    return;
  }
  showParamStatus(`refused (HTTP ${response.status})`, false);
  const errors = Array.isArray(body.errors) && body.errors.length ? body.errors : [{ message: body.detail || response.statusText }];
  ui.paramErrors.replaceChildren(...errors.map((e) => {
    const li = document.createElement("li");
    const where = e.field ? `${e.field} = ${JSON.stringify(e.value)}: ` : "";
    li.textContent = where + e.message + (e.allowed ? ` (allowed: ${e.allowed})` : "");
    const input = e.field && ui.editor.querySelector(`[data-path="${CSS.escape(e.field)}"]`);
    if (input) input.classList.add("invalid");
    return li;
  }));
}

ui.apply.addEventListener("click", applyParams);
ui.reset.addEventListener("click", () => { ui.paramErrors.replaceChildren(); showParamStatus("", true); renderEditor(); });

// ------------------------------------------------------------------ start

async function loadParams() {
  try {
    const [schema, current] = await Promise.all([getJSON("/params/schema"), getJSON("/params")]);
    store.schema = schema; store.params = current.params; store.version = current.version;
    ui.paramsInfo.textContent = `params v${current.version}`;
    renderEditor();
  } catch (err) {
    showParamStatus(`cannot load the parameters: ${err.message} (token needed?)`, false);
  }
}

ui.token.addEventListener("change", () => { if (!store.schema) loadParams(); });

async function start() {
  await loadParams();
  await refreshSensors();
  setInterval(refreshSensors, 1000);
  connect();
}

start();

// rls_uncertainty dashboard page (docs/dashboard.md). Reads the server's websocket only; every
// text from the node is inserted with textContent (never as HTML). Data kept per model is
// bounded (older half thinned at CAP samples); what is drawn is decimated to MAX_POINTS per
// series inside the selected window. The node computes every sample; only the drawing thins.
"use strict";

const CAP = 20000;           // samples kept per model (the newest half always at full rate)
const MAX_POINTS = 1500;     // points drawn per series
const DRAW_PERIOD_MS = 200;  // at most five redraws a second
const LATENCY_KEEP = 20000;  // latency records kept for the measurement (window.rlsLatency)
const MODEL_ORDER = ["CX", "CY", "CZ", "Cl", "Cm", "Cn"];  // Eq. 2's order; others after, by name
const GREEK = { alpha: "α", beta: "β", delta: "δ", theta: "θ", phi: "φ", psi: "ψ" };

const params = new URLSearchParams(location.search);
const token = params.get("token");
const state = { mode: "", reference: {}, models: new Map(), windowS: null, dirty: false, health: null };
window.rlsLatency = [];      // {published_ns, sent_ns, received_ms}: for benchmarks and tests
window.rlsState = state;

function el(tag, cls, text) {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
}

// "CZ_alpha" -> C with subscript "Zα"; "Cm_q_hat" -> "mq̂"; "CZ_delta_e" -> "Zδe"; "CZ_0" -> "Z0".
function typeset(name) {
  const m = /^C([A-Za-z])_(.+)$/.exec(name);
  if (!m) return null;
  let rest = m[2].replace(/_hat/g, "\u0302");
  for (const [word, letter] of Object.entries(GREEK)) rest = rest.replace(new RegExp(word, "g"), letter);
  const span = el("span", "typeset");
  span.append("C");
  span.append(el("sub", "", m[1] + rest.replace(/_/g, "")));
  return span;
}

function fmt(x, digits) { return Number.isFinite(x) ? x.toFixed(digits) : "–"; }

// ------------------------------------------------------------------ data
// state.models: model name -> { name, methods: { method: history }, quality: { method: quality
// message }, view }. The panels draw the estimates of PRIMARY (the recursive least squares of
// ~/M/...); a second estimation method's history and quality sit beside it under its own name.
const PRIMARY = "time";
const QUANTITIES = ["estimate", "se", "se_conventional", "converged"];

function modelFor(name) {
  let m = state.models.get(name);
  if (!m) { m = { name, methods: {}, quality: {}, view: null }; state.models.set(name, m); }
  return m;
}

function newHistory(names) {
  const cols = () => names.map(() => []);
  return { names, t: [], estimate: cols(), se: cols(), se_conventional: cols(), converged: cols() };
}

function thin(h) {
  const half = Math.floor(h.t.length / 2);
  const keep = (arr) => arr.filter((_, i) => i >= half || i % 2 === 0);
  h.t = keep(h.t);
  for (const q of QUANTITIES) h[q] = h[q].map(keep);
}

function appendColumns(method, name, cols, replace) {
  const m = modelFor(name);
  let h = m.methods[method];
  const sameNames = h && h.names.join(",") === cols.names.join(",");
  const goesBack = h && h.t.length && cols.t.length && cols.t[0] <= h.t[h.t.length - 1];
  if (!h || !sameNames || goesBack || replace) {
    h = m.methods[method] = newHistory(cols.names);
    if (method === PRIMARY && !sameNames) removeView(m);
  }
  for (let k = 0; k < cols.t.length; k++) h.t.push(cols.t[k]);
  for (const q of QUANTITIES) cols[q].forEach((values, i) => { for (const v of values) h[q][i].push(v); });
  while (h.t.length > CAP) thin(h);
  state.dirty = true;
}

function setQuality(msg) {
  modelFor(msg.model).quality[msg.method] = msg;
  state.dirty = true;
}

// ------------------------------------------------------------------ views
function removeView(m) {
  if (!m.view) return;
  m.view.section.remove();
  m.view.plots.forEach((p) => p.u.destroy());
  if (m.view.acf) m.view.acf.destroy();
  m.view = null;
}

function panelFor(m, names, i, container) {
  const name = names[i];
  const panel = el("div", "panel");
  panel.dataset.param = name;
  const head = el("div", "panel-head");
  const title = el("span", "title", name);
  const left = el("span");
  left.append(title);
  const ts = typeset(name);
  if (ts) { left.append(" "); left.append(ts); }
  const tags = el("span", "tags");
  const held = el("span", "held-tag", "HELD BACK");
  held.hidden = true;
  const badge = el("span", "badge", "not converged");
  badge.dataset.converged = "0";
  tags.append(held, badge);
  head.append(left, tags);
  const readout = el("div", "readout");
  const value = el("span", "value", "–");
  const se = el("span", "se");
  const ref = el("span", "ref");
  readout.append(value, se, ref);
  const ident = el("div", "ident");
  const chart = el("div", "chart");
  panel.append(head, readout, ident, chart);
  container.append(panel);
  const reference = state.reference[name];
  if (reference !== undefined) ref.textContent = "reference " + fmt(reference, 4);
  const series = [
    {},
    { label: "estimate", stroke: "#4fc3f7", width: 2 },
    { label: "+2σ corrected", stroke: "rgba(79,195,247,0.6)", width: 1 },
    { label: "−2σ corrected", stroke: "rgba(79,195,247,0.6)", width: 1 },
    { label: "+2σ conventional", stroke: "#ffb74d", width: 1, dash: [6, 4] },
    { label: "−2σ conventional", stroke: "#ffb74d", width: 1, dash: [6, 4] },
  ];
  if (reference !== undefined) series.push({ label: "reference", stroke: "#e0e0e0", width: 1, dash: [2, 3] });
  const opts = {
    width: Math.max(chart.clientWidth || 420, 300), height: 190, series, legend: { show: false },
    bands: [{ series: [2, 3], fill: "rgba(79,195,247,0.20)" }],
    scales: { x: { time: true } }, cursor: { drag: { x: false, y: false } },
    axes: [{ stroke: "#8b96a5", grid: { stroke: "#2a313c" } }, { stroke: "#8b96a5", grid: { stroke: "#2a313c" }, size: 70 }],
  };
  const u = new uPlot(opts, series.map(() => []), chart);
  return { name, panel, badge, held, value, se, ident, u, chart, reference };
}

// The residual autocorrelation at the retained lags with the 2σ white-noise bound (Fig. 5).
function acfChart(container) {
  const bars = uPlot.paths.bars({ size: [0.6, 12] });
  const series = [
    {},
    { label: "ρ inside ±2σ", stroke: "#4fc3f7", fill: "rgba(79,195,247,0.6)", paths: bars, points: { show: false } },
    { label: "ρ outside ±2σ", stroke: "#ffb74d", fill: "rgba(255,183,77,0.8)", paths: bars, points: { show: false } },
    { label: "+2σ", stroke: "#e0e0e0", width: 1, dash: [6, 4], points: { show: false } },
    { label: "−2σ", stroke: "#e0e0e0", width: 1, dash: [6, 4], points: { show: false } },
  ];
  const opts = {
    width: Math.max(container.clientWidth || 600, 300), height: 170, series, legend: { show: false },
    scales: { x: { time: false }, y: { range: (u, lo, hi) => [Math.min(-0.2, lo), Math.max(1, hi)] } },
    cursor: { drag: { x: false, y: false } },
    axes: [{ stroke: "#8b96a5", grid: { stroke: "#2a313c" }, label: "lag (samples)", labelSize: 18, size: 36 },
           { stroke: "#8b96a5", grid: { stroke: "#2a313c" }, size: 70 }],
  };
  return new uPlot(opts, series.map(() => []), container);
}

function viewFor(m, names) {
  if (m.view) return m.view;
  const section = el("section", "model");
  section.dataset.model = m.name;
  const head = el("div", "model-head");
  const fit = el("span", "fit");
  const status = el("span", "status");
  head.append(el("span", "name", m.name), fit, status);
  const panels = el("div", "panels");
  const acfBox = el("div", "autocorr");
  const acfTitle = el("div", "acf-title", "Residual autocorrelation at the retained lags, 2σ white-noise bound (Fig. 5)");
  const acfChartBox = el("div", "acf-chart");
  const why = el("div", "why");
  acfBox.append(acfTitle, acfChartBox, why);
  section.append(head, panels, acfBox);
  const models = document.getElementById("models");
  const rank = (name) => { const i = MODEL_ORDER.indexOf(name); return i < 0 ? MODEL_ORDER.length : i; };
  const before = (a, b) => rank(a) < rank(b) || (rank(a) === rank(b) && a < b);
  const after = [...models.children].find((s) => before(m.name, s.dataset.model));
  models.insertBefore(section, after || null);
  m.view = { section, fit, status, acfBox, acfChartBox, acfTitle, why, acf: null,
             plots: names.map((_, i) => panelFor(m, names, i, panels)) };
  return m.view;
}

function lowerBound(arr, x) {
  let lo = 0, hi = arr.length;
  while (lo < hi) { const mid = (lo + hi) >> 1; if (arr[mid] < x) lo = mid + 1; else hi = mid; }
  return lo;
}

// Indices of the samples drawn: those in the window, strided to MAX_POINTS, the newest always in.
function drawnIndices(t) {
  const n = t.length;
  const start = state.windowS ? lowerBound(t, t[n - 1] - state.windowS) : 0;
  const stride = Math.max(1, Math.ceil((n - start) / MAX_POINTS));
  const idx = [];
  for (let k = start; k < n; k += stride) idx.push(k);
  if (idx[idx.length - 1] !== n - 1) idx.push(n - 1);
  return idx;
}

function drawModel(m) {
  const h = m.methods[PRIMARY];
  if (!h || !h.t.length) return;
  const v = viewFor(m, h.names);
  const idx = drawnIndices(h.t);
  const x = idx.map((k) => h.t[k]);
  const last = h.t.length - 1;
  v.plots.forEach((p, i) => {
    const est = h.estimate[i], se = h.se[i], sc = h.se_conventional[i];
    const data = [x, idx.map((k) => est[k]), idx.map((k) => est[k] + 2 * se[k]), idx.map((k) => est[k] - 2 * se[k]),
                  idx.map((k) => est[k] + 2 * sc[k]), idx.map((k) => est[k] - 2 * sc[k])];
    if (p.reference !== undefined) data.push(x.map(() => p.reference));
    const width = Math.max(p.chart.clientWidth, 300);
    if (width !== p.u.width) p.u.setSize({ width, height: 190 });
    p.u.setData(data);
    p.value.textContent = fmt(est[last], 4);
    p.se.textContent = "";
    p.se.append("SE " + fmt(se[last], 4) + " ");
    p.se.append(el("span", "conv", "(conv. " + fmt(sc[last], 4) + ")"));
    const converged = h.converged[i][last] === 1 ? "1" : "0";
    p.badge.dataset.converged = converged;
    p.badge.textContent = converged === "1" ? "CONVERGED" : "not converged";
    p.panel.classList.toggle("converged", converged === "1");
  });
}

// Per parameter: identifiable or why not (from ~/M/identifiability), held back from
// "converged" by the node (its /diagnostics); per model: R², Fig. 5 and the node's words.
function drawQuality(m) {
  if (!m.view) return;
  const v = m.view;
  const q = m.quality[PRIMARY];
  const diag = state.health && state.health.models ? state.health.models[m.name] : null;
  const held = new Set(diag && diag.held_back ? diag.held_back.split(",").filter(Boolean) : []);
  for (const p of v.plots) {
    const info = q && q.parameters ? q.parameters[p.name] : null;
    p.held.hidden = !held.has(p.name);
    p.panel.classList.toggle("held-back", held.has(p.name));
    if (!info) { p.ident.textContent = ""; p.ident.dataset.identifiable = ""; continue; }
    p.ident.dataset.identifiable = info.identifiable ? "1" : "0";
    if (info.identifiable) {
      p.ident.textContent = "identifiable" + (info.partner ? `  ·  ρ ${fmt(info.correlation, 2)} with ${info.partner}` : "");
    } else {
      p.ident.textContent = "not identifiable: " + info.reason;
    }
  }
  const fit = q ? q.fit : null;
  if (fit) {
    v.fit.textContent = `R² ${fmt(fit.r_squared, 3)}  ·  ${fit.rho.length} lags  ·  ` +
      `${fmt(100 * fit.outside, 0)}% outside ±2σ (${fmt(fit.bound_2sigma, 3)})`;
    v.acfBox.dataset.shown = "1";
    if (!v.acf) v.acf = acfChart(v.acfChartBox);
    const lags = fit.rho.map((_, i) => i + 1);
    const b = fit.bound_2sigma;
    const width = Math.max(v.acfChartBox.clientWidth, 300);
    if (width !== v.acf.width) v.acf.setSize({ width, height: 170 });
    v.acf.setData([lags, fit.rho.map((r) => (Math.abs(r) <= b ? r : null)), fit.rho.map((r) => (Math.abs(r) > b ? r : null)),
                   lags.map(() => b), lags.map(() => -b)]);
  } else if (diag && diag.ready === "True") {  // a node without ~/M/fit: its diagnostics' figures
    v.fit.textContent = `R² ${fmt(parseFloat(diag.r_squared), 3)}  ·  lags ${diag.lags}  ·  residual ρ₁ ` +
      fmt(parseFloat(diag.residual_rho1), 2);
  }
  v.why.textContent = q && q.node_text ? q.node_text : (diag && diag.identifiability) || "";
  v.status.textContent = diag ? (diag.ready === "True" ? (diag.converged === "True" ? "converged" : "") : (diag.message || "")) : "";
}

function draw() {
  state.dirty = false;
  let newest = -Infinity;
  for (const m of state.models.values()) {
    drawModel(m);
    drawQuality(m);
    const h = m.methods[PRIMARY];
    if (h && h.t.length) newest = Math.max(newest, h.t[h.t.length - 1]);
  }
  if (Number.isFinite(newest)) {
    const d = new Date(newest * 1000);
    document.getElementById("clock").textContent = "t = " + d.toISOString().replace("T", " ").slice(0, 22) + " UTC";
  }
}

// ------------------------------------------------------------------ health
function drawHealth(msg) {
  state.health = msg.health;
  const banner = document.getElementById("banner");
  banner.dataset.state = msg.state;
  banner.textContent = msg.text;
  const h = msg.health;
  const inputs = document.getElementById("inputs");
  const tbody = document.querySelector("#streams tbody");
  tbody.textContent = "";
  if (h) {
    inputs.dataset.level = h.inputs.level;
    const level = document.getElementById("inputs-level");
    level.dataset.level = h.inputs.level;
    level.textContent = ["OK", "WARN", "ERROR", "STALE"][h.inputs.level] || "";
    document.getElementById("inputs-message").textContent = h.inputs.message;
    for (const s of h.inputs.streams) {
      const tr = el("tr");
      const recent = parseInt(s["recent.rejected"] || "0", 10);
      const problem = recent > 0 || parseInt(s["recent.missing"] || "0", 10) > 0 || parseInt(s["recent.expired"] || "0", 10) > 0;
      const silent = s.required === "True" && s.age_s === "never received";
      if (problem || silent) tr.className = h.inputs.level >= 2 ? "error" : "warn";
      tr.dataset.stream = s.name;
      const reasons = el("div", "reasons",
        Object.entries(s.recent_reasons || {}).map(([r, n]) => `${r} ${n}`).join(", "));
      const rejected = el("td", "", String(recent));
      rejected.append(reasons);
      tr.append(el("td", "", s.name + (s.required === "True" ? "" : " (optional)")), el("td", "", s.rate_hz || ""),
                el("td", "", s.age_s || ""), el("td", "", s.publishers || ""), el("td", "", s.accepted || ""), rejected);
      tbody.append(tr);
    }
    document.getElementById("samples-message").textContent = h.samples.message || "";
    const rej = Object.entries(h.samples).filter(([k]) => k.startsWith("samples_rejected."))
      .map(([k, v]) => `${k.slice(17)} ${v}`).join(", ");
    document.getElementById("samples-detail").textContent =
      `pending ${h.samples.samples_pending || 0}; rejected: ${rej || "none"}; enabled: ${h.samples.enabled}`;
  }
  const socket = msg.socket || {};
  const dropped = Object.entries(msg.dropped || {}).map(([k, v]) => `${k} ${v}`).join(", ") || "none";
  document.getElementById("footer").textContent =
    `arrays dropped: ${dropped}; display history restarts: ${msg.history_resets || 0}; ` +
    `socket: malformed ${socket.malformed || 0}, oversized ${socket.oversized || 0}, resyncs ${socket.resyncs || 0}`;
  state.dirty = true;
}

// ------------------------------------------------------------------ socket
function onMessage(msg) {
  if (msg.type === "hello") {
    state.mode = msg.mode;
    state.reference = msg.reference || {};
    const mode = document.getElementById("mode");
    mode.textContent = msg.mode === "live" ? "LIVE" : "REPLAY";
    mode.className = "tag " + msg.mode;
    document.getElementById("node").textContent = msg.mode === "live"
      ? `${msg.node}  ·  ROS_DOMAIN_ID=${msg.domain}  ·  ${msg.discovery_range}`
      : `${msg.replay_dir}  ·  ${msg.node}`;
    if (state.windowS === null) setWindow(params.has("window") ? Number(params.get("window")) : (msg.mode === "live" ? 60 : 0));
  } else if (msg.type === "snapshot") {
    for (const m of state.models.values()) removeView(m);
    state.models.clear();
    for (const [method, models] of Object.entries(msg.methods)) {
      for (const [name, cols] of Object.entries(models)) appendColumns(method, name, cols, true);
    }
    for (const q of msg.quality) setQuality(q);
  } else if (msg.type === "samples") {
    const received = performance.timeOrigin + performance.now();
    for (const [name, cols] of Object.entries(msg.models)) appendColumns(msg.method, name, cols, false);
    if (window.rlsLatency.length < LATENCY_KEEP) {
      window.rlsLatency.push({ published_ns: msg.published_ns, sent_ns: msg.sent_ns, received_ms: received,
                               stamp: Math.max(...Object.values(msg.models).map((c) => c.t[c.t.length - 1])) });
    }
  } else if (msg.type === "quality") {
    setQuality(msg);
  } else if (msg.type === "health") {
    drawHealth(msg);
  }
}

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws" +
    (token ? "?token=" + encodeURIComponent(token) : "");
  const ws = new WebSocket(url);
  let ping = null;
  ws.onopen = () => { ping = setInterval(() => ws.send('{"type":"ping"}'), 15000); };
  ws.onmessage = (event) => onMessage(JSON.parse(event.data));
  ws.onclose = () => {
    clearInterval(ping);
    const banner = document.getElementById("banner");
    banner.dataset.state = "disconnected";
    banner.textContent = "Connection to the dashboard server lost; retrying every 2 s.";
    setTimeout(connect, 2000);
  };
}

function setWindow(seconds) {
  state.windowS = seconds;
  for (const b of document.querySelectorAll("nav#window button")) {
    b.classList.toggle("active", Number(b.dataset.window) === seconds);
  }
  state.dirty = true;
}

for (const b of document.querySelectorAll("nav#window button")) b.addEventListener("click", () => setWindow(Number(b.dataset.window)));
setInterval(() => { if (state.dirty) draw(); }, DRAW_PERIOD_MS);
connect();

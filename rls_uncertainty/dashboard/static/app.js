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
// counts: the server's samples shown per method and model (the "count" of its messages);
// drawn: per method and model, the count and newest time the last draw showed (for tests).
// t0: the time of the first sample (s), origin of the time axis unless clock is "utc"; yAll: the
// y-range holds every sample shown, else the rule of docs/dashboard.md ("What the plots show").
const state = { mode: "", reference: {}, models: new Map(), windowS: null, dirty: false, health: null,
                counts: {}, drawn: {}, t0: null, clock: "relative", yAll: false, units: {},
                range: { quantile: 0.05, pad: 0.08, transient: 0.2 } };
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

// Decimals that show a standard error to two significant digits (and its estimate to the same
// place): 0.0043 -> 4, 0.43 -> 2, 23 -> 0; at most 12.
function decimals(se) {
  if (!(se > 0) || !Number.isFinite(se)) return 4;
  return Math.min(12, Math.max(0, 1 - Math.floor(Math.log10(se))));
}

// Percent error 100 SE / |estimate|, one decimal ("–" when the estimate is 0).
function percent(est, se) { return est !== 0 && Number.isFinite(est) ? fmt(100 * se / Math.abs(est), 1) + " %" : "–"; }

// "CZ_alpha" -> "1/rad"; "Cm_q" -> "1/rad (per q cbar/2V)"; "CZ_0" -> "dimensionless" (the server's table).
function unitOf(name) { const i = name.indexOf("_"); return i < 0 ? "" : state.units[name.slice(i + 1)] || ""; }

// numpy.quantile's default (linear interpolation, its rounding) of an unsorted array.
function quantile(values, q) {
  const a = Float64Array.from(values).sort();
  const pos = q * (a.length - 1), lo = Math.floor(pos), hi = Math.min(lo + 1, a.length - 1), g = pos - lo;
  const d = a[hi] - a[lo];
  return g >= 0.5 ? a[hi] - d * (1 - g) : a[lo] + d * g;
}

// The y-range of an estimate and its ±2σ band (datapath/display.py's band_limits): the
// quantiles of the band's edges, widened to hold the newest band, padded.
function bandLimits(est, se) {
  const n = est.length;
  if (n < 2) return null;
  const { quantile: q, pad } = state.range;
  const lo = Math.min(quantile(est.map((v, k) => v - 2 * se[k]), q), est[n - 1] - 2 * se[n - 1]);
  const hi = Math.max(quantile(est.map((v, k) => v + 2 * se[k]), 1 - q), est[n - 1] + 2 * se[n - 1]);
  const span = hi > lo ? hi - lo : Math.max(Math.abs(hi), 1e-12);
  return [lo - pad * span, hi + pad * span];
}

// ------------------------------------------------------------------ data
// state.models: model name -> { name, methods: { method: history }, quality: { method: quality
// message }, view }. Methods (docs/dashboard.md, "Two estimation methods"): "time", the
// recursive least squares of ~/M/..., and "frequency", the frequency-domain estimator of
// ~/M/frequency/... (no bias parameter). A model's panels show every method present, matched by
// parameter name; the first present (time domain when there) is drawn as before, with its
// conventional bounds; another is drawn beside it in its own colour with its corrected band.
const QUALITY_METHOD = "time";  // fit, autocorrelation and identifiability: the time domain's
const QUANTITIES = ["estimate", "se", "se_conventional", "converged"];
const METHODS = {
  time: { label: "time domain (RLS)", stroke: "#4fc3f7", edge: "rgba(79,195,247,0.6)", fill: "rgba(79,195,247,0.20)" },
  frequency: { label: "frequency domain", stroke: "#f06292", edge: "rgba(240,98,146,0.6)", fill: "rgba(240,98,146,0.16)" },
};
const METHOD_ORDER = Object.keys(METHODS);
const methodStyle = (k) => METHODS[k] || { label: k, stroke: "#aed581", edge: "rgba(174,213,129,0.6)", fill: "rgba(174,213,129,0.16)" };

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

function appendColumns(method, name, cols) {
  const m = modelFor(name);
  if (cols.count !== undefined) (state.counts[method] ||= {})[name] = cols.count;
  if (cols.t.length && (state.t0 === null || cols.t[0] < state.t0)) state.t0 = cols.t[0];
  let h = m.methods[method];
  const sameNames = h && h.names.join(",") === cols.names.join(",");
  const goesBack = h && h.t.length && cols.t.length && cols.t[0] <= h.t[h.t.length - 1];
  if (!h || !sameNames || goesBack) h = m.methods[method] = newHistory(cols.names);
  for (let k = 0; k < cols.t.length; k++) h.t.push(cols.t[k]);
  for (const q of QUANTITIES) cols[q].forEach((values, i) => { for (const v of values) h[q][i].push(v); });
  while (h.t.length > CAP) thin(h);
  state.dirty = true;
}

function setQuality(msg) {
  modelFor(msg.model).quality[msg.method] = msg;
  state.dirty = true;
}

// What a model's view shows: its methods with samples (time domain first) and the parameters,
// the first method's in its order, then any only another method has. A change rebuilds the view.
function layoutOf(m) {
  const rank = (k) => { const i = METHOD_ORDER.indexOf(k); return i < 0 ? METHOD_ORDER.length : i; };
  const methods = Object.keys(m.methods).filter((k) => m.methods[k].t.length).sort((a, b) => rank(a) - rank(b) || (a < b ? -1 : 1));
  if (!methods.length) return null;
  const names = [...m.methods[methods[0]].names];
  for (const k of methods.slice(1)) for (const n of m.methods[k].names) if (!names.includes(n)) names.push(n);
  return { methods, names, key: methods.join("+") + ":" + names.join(",") };
}

// ------------------------------------------------------------------ views
function removeView(m) {
  if (!m.view) return;
  m.view.section.remove();
  m.view.plots.forEach((p) => p.u.destroy());
  if (m.view.acf) m.view.acf.destroy();
  m.view = null;
}

// One readout row per method: the first method's is the panel's large readout (and the head's
// badge its flag); another's a row under it, labelled with its method and colour.
function readoutRow(method, first, labelled, badge) {
  const row = el("div", first ? "readout" : "readout alt");
  row.dataset.method = method;
  const style = methodStyle(method);
  if (labelled) {
    row.append(el("span", "method", style.label));
  }
  const value = el("span", first ? "value" : "alt-value", "–");
  const se = el("span", first ? "se" : "alt-se");
  const pct = el("span", "pct");
  pct.title = "percent error, 100 SE / |estimate|";
  row.append(value, se, pct);
  if (!first) { badge = el("span", "alt-badge", "not converged"); badge.dataset.converged = "0"; row.append(badge); }
  return { row, value, se, pct, badge };
}

function chartSeries(methods, reference) {
  const series = [{}];
  const slots = {};
  const bands = [];
  methods.forEach((k, j) => {
    const s = methodStyle(k);
    const label = j ? s.label + " " : "";
    slots[k] = series.length;
    // Another method's estimate is drawn thinner, over the first's: where they agree both show.
    series.push({ label: label + "estimate", stroke: s.stroke, width: j ? 1.25 : 2, spanGaps: true },
                { label: label + "+2σ corrected", stroke: s.edge, width: 1, spanGaps: true },
                { label: label + "−2σ corrected", stroke: s.edge, width: 1, spanGaps: true });
    bands.push({ series: [slots[k] + 1, slots[k] + 2], fill: s.fill });
    if (j === 0) {
      series.push({ label: "+2σ conventional", stroke: "#ffb74d", width: 1, dash: [6, 4], spanGaps: true },
                  { label: "−2σ conventional", stroke: "#ffb74d", width: 1, dash: [6, 4], spanGaps: true });
    }
  });
  if (reference !== undefined) series.push({ label: "reference", stroke: "#e0e0e0", width: 1, dash: [2, 3] });
  return { series, slots, bands };
}

function panelFor(m, layout, name, container) {
  const panel = el("div", layout.methods.length > 1 ? "panel two" : "panel");
  panel.dataset.param = name;
  const head = el("div", "panel-head");
  const title = el("span", "title", name);
  const left = el("span");
  left.append(title);
  const ts = typeset(name);
  if (ts) { left.append(" "); left.append(ts); }
  left.append(el("span", "unit", unitOf(name)));
  const tags = el("span", "tags");
  const held = el("span", "held-tag", "HELD BACK");
  held.hidden = true;
  const badge = el("span", "badge", "not converged");
  badge.dataset.converged = "0";
  tags.append(held, badge);
  head.append(left, tags);
  const labelled = layout.methods.length > 1;
  const rows = {};
  layout.methods.forEach((k, j) => { rows[k] = readoutRow(k, j === 0, labelled, badge); });
  const first = rows[layout.methods[0]].row;
  const ref = el("span", "ref");
  first.append(ref);
  const pstate = el("div", "pstate");
  const ident = el("div", "ident");
  const chart = el("div", "chart");
  panel.append(head, ...layout.methods.map((k) => rows[k].row), pstate, ident, chart);
  container.append(panel);
  const reference = state.reference[name];
  const { series, slots, bands } = chartSeries(layout.methods, reference);
  const p = { name, panel, badge, held, rows, slots, pstate, ident, chart, reference, ref, yRange: null };
  const utc = state.clock === "utc";
  const opts = {
    width: Math.max(chart.clientWidth || 420, 300), height: 190, series, legend: { show: false }, bands,
    scales: { x: { time: utc }, y: { range: (u, lo, hi) => p.yRange || uPlot.rangeNum(lo, hi, 0.1, true) } },
    cursor: { drag: { x: false, y: false } },
    axes: [{ stroke: "#8b96a5", grid: { stroke: "#2a313c" } }, { stroke: "#8b96a5", grid: { stroke: "#2a313c" }, size: 70 }],
  };
  if (utc) opts.tzDate = (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC");
  p.u = new uPlot(opts, series.map(() => []), chart);
  return p;
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

// Which colour is which method, in the model's head, when it is not the time domain alone.
function methodLegend(methods) {
  const legend = el("span", "legend");
  for (const k of methods) {
    const item = el("span", "legend-item");
    item.dataset.method = k;
    item.append(el("span", "swatch"), methodStyle(k).label);
    legend.append(item);
  }
  legend.append(el("span", "dim", "· shaded: corrected ±2σ · dashed: conventional ±2σ, " + methodStyle(methods[0]).label));
  return legend;
}

function viewFor(m, layout) {
  if (m.view) return m.view;
  const section = el("section", "model");
  section.dataset.model = m.name;
  const head = el("div", "model-head");
  const fit = el("span", "fit");
  const status = el("span", "status");
  head.append(el("span", "name", m.name), fit, status);
  if (layout.methods.length > 1 || layout.methods[0] !== "time") head.append(methodLegend(layout.methods));
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
  m.view = { key: layout.key, section, fit, status, acfBox, acfChartBox, acfTitle, why, acf: null,
             plots: layout.names.map((name) => panelFor(m, layout, name, panels)) };
  return m.view;
}

function lowerBound(arr, x) {
  let lo = 0, hi = arr.length;
  while (lo < hi) { const mid = (lo + hi) >> 1; if (arr[mid] < x) lo = mid + 1; else hi = mid; }
  return lo;
}

// Indices of the samples drawn: those in the window ending at `end`, strided to MAX_POINTS,
// the newest always in.
function windowStart(t, end) { return state.windowS ? lowerBound(t, end - state.windowS) : 0; }

function drawnIndices(t, end) {
  const n = t.length;
  const start = windowStart(t, end);
  const stride = Math.max(1, Math.ceil((n - start) / MAX_POINTS));
  const idx = [];
  for (let k = start; k < n; k += stride) idx.push(k);
  if (idx[idx.length - 1] !== n - 1) idx.push(n - 1);
  return idx;
}

// The drawn samples of every method on one time axis: x (sorted, each time once) and, per
// method, its drawn indices and their positions in x (a method's values are null elsewhere).
function commonAxis(m, methods) {
  const end = Math.max(...methods.map((k) => m.methods[k].t.at(-1)));
  const drawn = methods.map((k) => { const h = m.methods[k]; return { k, h, idx: drawnIndices(h.t, end), start: windowStart(h.t, end) }; });
  const origin = state.clock === "utc" ? 0 : state.t0;
  if (drawn.length === 1) {
    const d = drawn[0];
    d.pos = d.idx.map((_, j) => j);
    return { x: d.idx.map((k) => d.h.t[k] - origin), drawn };
  }
  const x = [...new Set(drawn.flatMap((d) => d.idx.map((k) => d.h.t[k])))].sort((a, b) => a - b);
  for (const d of drawn) d.pos = d.idx.map((k) => lowerBound(x, d.h.t[k]));
  return { x: x.map((v) => v - origin), drawn };
}

// The y-range of a panel (docs/dashboard.md, "What the plots show"): per method, over the samples
// of the window after its first `transient` fraction, bandLimits; their union. Null: every sample.
function yRangeOf(p, drawn) {
  if (state.yAll) return null;
  let lo = Infinity, hi = -Infinity;
  for (const d of drawn) {
    const i = d.h.names.indexOf(p.name);
    if (i < 0) continue;
    const n = d.h.t.length - d.start;
    const from = d.start + Math.floor(state.range.transient * n);
    const limits = bandLimits(d.h.estimate[i].slice(from), d.h.se[i].slice(from));
    if (limits) { lo = Math.min(lo, limits[0]); hi = Math.max(hi, limits[1]); }
  }
  return Number.isFinite(lo) ? [lo, hi] : null;
}

// The reference's verdict: how many corrected standard errors the estimate is from it.
function showReference(p, h, i) {
  if (p.reference === undefined) return;
  const last = h.t.length - 1;
  const est = i < 0 ? NaN : h.estimate[i][last], se = i < 0 ? NaN : h.se[i][last];
  const sigmas = Math.abs(est - p.reference) / se;
  p.ref.textContent = "reference " + fmt(p.reference, decimals(se)) + (Number.isFinite(sigmas) ? `  ·  ${fmt(sigmas, 1)}σ off` : "");
  p.ref.dataset.sigmas = Number.isFinite(sigmas) ? String(sigmas) : "";
  p.ref.dataset.verdict = !Number.isFinite(sigmas) ? "" : sigmas <= 2 ? "within" : "outside";
}

function clearReadout(row) {
  row.value.textContent = "–";
  row.se.textContent = "";
  row.pct.textContent = "";
  row.badge.dataset.converged = "0";
  row.badge.textContent = "not converged";
}

function showReadout(row, h, i, primary) {
  const last = h.t.length - 1;
  if (i < 0) {  // a parameter this method does not estimate (the frequency domain's bias)
    row.value.textContent = "–";
    row.se.textContent = "not estimated";
    row.pct.textContent = "";
    row.badge.hidden = !primary;
    return false;
  }
  const est = h.estimate[i][last], se = h.se[i][last], sc = h.se_conventional[i][last];
  row.value.textContent = fmt(est, decimals(se));
  row.se.textContent = "";
  row.se.append("SE " + fmt(se, decimals(se)) + " ");
  row.se.append(el("span", "conv", "(conv. " + fmt(sc, decimals(sc)) + ")"));
  row.pct.textContent = percent(est, se);
  const converged = h.converged[i][last] === 1 ? "1" : "0";
  row.badge.hidden = false;
  row.badge.dataset.converged = converged;
  row.badge.textContent = converged === "1" ? "CONVERGED" : "not converged";
  return converged === "1";
}

function drawModel(m) {
  const layout = layoutOf(m);
  if (!layout) return;
  if (m.view && m.view.key !== layout.key) removeView(m);
  const v = viewFor(m, layout);
  const { x, drawn } = commonAxis(m, layout.methods);
  const column = (d, values, f) => {
    const out = new Array(x.length).fill(null);
    if (values) d.idx.forEach((k, j) => { out[d.pos[j]] = f(k); });
    return out;
  };
  v.plots.forEach((p) => {
    const data = [x];
    drawn.forEach((d, j) => {
      const i = d.h.names.indexOf(p.name);
      const est = d.h.estimate[i], se = d.h.se[i], sc = d.h.se_conventional[i];
      data.push(column(d, est, (k) => est[k]), column(d, est, (k) => est[k] + 2 * se[k]),
                column(d, est, (k) => est[k] - 2 * se[k]));
      if (j === 0) data.push(column(d, est, (k) => est[k] + 2 * sc[k]), column(d, est, (k) => est[k] - 2 * sc[k]));
      const converged = showReadout(p.rows[d.k], d.h, i, j === 0);
      if (j === 0) { p.panel.classList.toggle("converged", converged); showReference(p, d.h, i); }
    });
    p.yRange = yRangeOf(p, drawn);
    if (p.reference !== undefined) data.push(x.map(() => p.reference));
    const width = Math.max(p.chart.clientWidth, 300);
    if (width !== p.u.width) p.u.setSize({ width, height: 190 });
    p.u.setData(data);
  });
}

// Per parameter: identifiable or why not (from ~/M/identifiability), held back from
// "converged" by the node (its /diagnostics); per model: R², Fig. 5 and the node's words.
function drawQuality(m) {
  if (!m.view) return;
  const v = m.view;
  const q = m.quality[QUALITY_METHOD];
  const diag = state.health && state.health.models ? state.health.models[m.name] : null;
  const held = new Set(diag && diag.held_back ? diag.held_back.split(",").filter(Boolean) : []);
  const layout = layoutOf(m);
  const methods = layout ? layout.methods : [];  // time domain first
  for (const p of v.plots) {
    showState(p, diag, methods.length > 1 ? methods : []);
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

// A parameter's state in words from the node's /diagnostics (state.<p>, frequency.state.<p>):
// converged, settling, held back: <reason>, initializing (k of N samples), withheld.
function showState(p, diag, methods) {
  const key = (k) => (k === "time" ? "" : k + ".") + "state." + p.name;
  const parts = (methods.length ? methods : ["time"]).filter((k) => diag && diag[key(k)] !== undefined)
    .map((k) => (methods.length ? methodStyle(k).label + ": " : "") + diag[key(k)]);
  p.pstate.textContent = parts.join("  ·  ");
  p.pstate.dataset.state = diag && diag[key("time")] !== undefined ? diag[key("time")].split(/[:( ]/)[0] : "";
}

// The node reset: what it showed is gone. The panels stay, emptied, until its next samples
// (their state lines say how far the node's models are).
function clearModels() {
  for (const m of state.models.values()) {
    m.methods = {};
    m.quality = {};
    if (!m.view) continue;
    for (const p of m.view.plots) {
      for (const row of Object.values(p.rows)) clearReadout(row);
      p.panel.classList.remove("converged");
      if (p.reference !== undefined) { p.ref.textContent = "reference " + fmt(p.reference, 4); p.ref.dataset.verdict = ""; }
      p.u.setData(p.u.series.map(() => []));
    }
    m.view.fit.textContent = "";
    if (m.view.acf) { m.view.acf.destroy(); m.view.acf = null; }
    m.view.acfBox.dataset.shown = "";
  }
  state.counts = {};
  state.t0 = null;
  state.dirty = true;
}

function draw() {
  state.dirty = false;
  let newest = -Infinity;
  const drawn = {};
  let total = 0;
  for (const m of state.models.values()) {
    drawModel(m);
    drawQuality(m);
    for (const [k, h] of Object.entries(m.methods)) {
      if (!h.t.length) continue;
      newest = Math.max(newest, h.t[h.t.length - 1]);
      const count = (state.counts[k] || {})[m.name] || 0;
      (drawn[k] ||= {})[m.name] = { count, t: h.t[h.t.length - 1] };
      total += count;
    }
  }
  state.drawn = drawn;
  document.getElementById("models").dataset.drawn = String(total);
  const clock = document.getElementById("clock");
  if (!Number.isFinite(newest)) clock.textContent = "";
  else if (state.clock === "utc") clock.textContent = "t = " + new Date(newest * 1000).toISOString().replace("T", " ").slice(0, 22) + " UTC";
  else clock.textContent = `t = ${fmt(newest - state.t0, 2)} s since the first sample`;
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
  const listed = (counts) => Object.entries(counts || {}).filter(([, v]) => v).map(([k, v]) => `${k} ${v}`).join(", ") || "none";
  document.getElementById("footer").textContent =
    `arrays dropped: ${listed(msg.dropped)}; samples refused: ${listed(msg.refused)}; ` +
    `display history restarts: ${msg.history_resets || 0}; ` +
    `socket: malformed ${socket.malformed || 0}, oversized ${socket.oversized || 0}, resyncs ${socket.resyncs || 0}; ` +
    `connections refused: ${listed(socket.refused)}`;
  state.dirty = true;
}

// ------------------------------------------------------------------ socket
function onMessage(msg) {
  if (msg.type === "hello") {
    state.mode = msg.mode;
    state.reference = msg.reference || {};
    state.units = msg.units || {};
    if (msg.range) state.range = msg.range;
    const mode = document.getElementById("mode");
    mode.textContent = msg.mode === "live" ? "LIVE" : "REPLAY";
    mode.className = "tag " + msg.mode;
    document.getElementById("node").textContent = msg.mode === "live"
      ? `${msg.node}  ·  ROS_DOMAIN_ID=${msg.domain}  ·  ${msg.discovery_range}`
      : `${msg.replay_dir}  ·  ${msg.node}`;
    if (state.windowS === null) setWindow(params.has("window") ? Number(params.get("window")) : (msg.mode === "live" ? 60 : 0));
  } else if (msg.type === "snapshot") {
    // The page starts over; the histories follow as "samples" messages marked "snapshot".
    for (const m of state.models.values()) removeView(m);
    state.models.clear();
    state.counts = {};
    state.t0 = null;
    for (const q of msg.quality) setQuality(q);
    state.dirty = true;
  } else if (msg.type === "samples") {
    const received = performance.timeOrigin + performance.now();
    for (const [name, cols] of Object.entries(msg.models)) appendColumns(msg.method, name, cols);
    if (!msg.snapshot && window.rlsLatency.length < LATENCY_KEEP) {
      window.rlsLatency.push({ published_ns: msg.published_ns, sent_ns: msg.sent_ns, received_ms: received,
                               stamp: Math.max(...Object.values(msg.models).map((c) => c.t[c.t.length - 1])) });
    }
  } else if (msg.type === "reset") {
    clearModels();
  } else if (msg.type === "quality") {
    setQuality(msg);
  } else if (msg.type === "health") {
    drawHealth(msg);
    drawTargets(msg.health);
  } else if (msg.type === "flight") {
    drawFlight(msg);
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

// y: the rule's range or every sample; time: since the first sample or UTC (the plots rebuilt).
function setView(yAll, clock) {
  const rebuild = clock !== state.clock;
  state.yAll = yAll;
  state.clock = clock;
  document.getElementById("y-all").classList.toggle("active", yAll);
  document.getElementById("clock-utc").classList.toggle("active", clock === "utc");
  if (rebuild) for (const m of state.models.values()) removeView(m);
  state.dirty = true;
}

for (const b of document.querySelectorAll("nav#window button")) b.addEventListener("click", () => setWindow(Number(b.dataset.window)));
document.getElementById("y-all").addEventListener("click", () => setView(!state.yAll, state.clock));
document.getElementById("clock-utc").addEventListener("click", () => setView(state.yAll, state.clock === "utc" ? "relative" : "utc"));
setView(params.get("y") === "all", params.get("clock") === "utc" ? "utc" : "relative");
setInterval(() => { if (state.dirty) draw(); }, DRAW_PERIOD_MS);
connect();

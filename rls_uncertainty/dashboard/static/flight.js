// rls_uncertainty dashboard: the flight so far (docs/dashboard.md, "The flight so far"). Draws the
// server's "flight" message (the node's maneuver history) as the paper's Fig. 12 per parameter and
// its Table 4, and the current test point's targets from the node's /diagnostics. Uses el(),
// typeset() and state from app.js (loaded after this file); every text is set with textContent.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const FIG = { w: 330, h: 190, left: 62, right: 8, top: 10, bottom: 34 };
const flight = { message: null };
window.rlsFlight = flight;

function svgEl(tag, attrs) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, String(v));
  return e;
}

function num(x, digits) { return x === null || x === undefined || !Number.isFinite(x) ? "–" : x.toPrecision(digits); }

// A numeric table cell: the value at full precision in data-value (tests read it), shown rounded.
function cell(col, x, digits) {
  const td = document.createElement("td");
  td.dataset.col = col;
  td.dataset.value = x === null || x === undefined ? "" : String(x);
  td.textContent = typeof x === "number" ? num(x, digits) : (x === null || x === undefined ? "–" : String(x));
  return td;
}

// The rows Fig. 12 draws for one parameter and method: per maneuver its row of status ok (or null).
function seriesOf(msg, model, parameter, method) {
  return msg.maneuvers.map((m) => m.rows.find((r) => r.model === model && r.parameter === parameter &&
    r.method === method && r.status === "ok" && r.estimate !== null) || null);
}

// Fig. 12 of one parameter: each maneuver's final estimate with its corrected (wide, light) and
// conventional (narrow, orange) 2-sigma bars, the mean over the maneuvers (a line) and the band
// of the scatter (mean +- one sample standard deviation).
function figure12(msg, t4) {
  const rows = seriesOf(msg, t4.model, t4.parameter, t4.method);
  const box = document.createElement("div");
  box.className = "fig12";
  box.dataset.parameter = t4.parameter;
  box.dataset.method = t4.method;
  const head = document.createElement("div");
  head.className = "fig12-head";
  head.append(typeset(t4.parameter) || t4.parameter);
  if (t4.method !== "time") head.append(" (" + t4.method + ")");
  box.append(head);
  const svg = svgEl("svg", { viewBox: `0 0 ${FIG.w} ${FIG.h}`, width: FIG.w, height: FIG.h, role: "img" });
  box.append(svg);
  const lo = [], hi = [];
  for (const r of rows) {
    if (!r) continue;
    const half = 2 * Math.max(r.se_corrected || 0, r.se_conventional || 0);
    lo.push(r.estimate - half); hi.push(r.estimate + half);
  }
  if (t4.mean !== null && t4.scatter !== null) { lo.push(t4.mean - t4.scatter); hi.push(t4.mean + t4.scatter); }
  if (!lo.length) return box;
  let y0 = Math.min(...lo), y1 = Math.max(...hi);
  if (!(y1 > y0)) { y0 -= 1e-9 + Math.abs(y0) * 0.1; y1 += 1e-9 + Math.abs(y1) * 0.1; }
  const pad = 0.06 * (y1 - y0);
  y0 -= pad; y1 += pad;
  const n = rows.length;
  const X = (i) => FIG.left + (i + 0.5) * (FIG.w - FIG.left - FIG.right) / n;
  const Y = (v) => FIG.top + (y1 - v) / (y1 - y0) * (FIG.h - FIG.top - FIG.bottom);
  axes(svg, msg, y0, y1, X, Y);
  if (t4.mean !== null) {
    if (t4.scatter !== null) {
      svg.append(svgEl("rect", { class: "band", x: FIG.left, width: FIG.w - FIG.left - FIG.right,
                                 y: Y(t4.mean + t4.scatter), height: Y(t4.mean - t4.scatter) - Y(t4.mean + t4.scatter) }));
    }
    svg.append(svgEl("line", { class: "mean", x1: FIG.left, x2: FIG.w - FIG.right, y1: Y(t4.mean), y2: Y(t4.mean) }));
  }
  rows.forEach((r, i) => { if (r) bars(svg, r, X(i), Y); });
  return box;
}

function bars(svg, r, x, Y) {
  const g = svgEl("g", { class: "maneuver" });
  if (r.se_corrected !== null) {
    g.append(svgEl("rect", { class: "corrected", x: x - 5, width: 10, y: Y(r.estimate + 2 * r.se_corrected),
                             height: Y(r.estimate - 2 * r.se_corrected) - Y(r.estimate + 2 * r.se_corrected) }));
  }
  if (r.se_conventional !== null) {
    g.append(svgEl("line", { class: "conventional", x1: x, x2: x, y1: Y(r.estimate + 2 * r.se_conventional),
                             y2: Y(r.estimate - 2 * r.se_conventional) }));
  }
  g.append(svgEl("circle", { class: "estimate", cx: x, cy: Y(r.estimate), r: 3.5 }));
  svg.append(g);
}

function axes(svg, msg, y0, y1, X, Y) {
  const x1 = FIG.w - FIG.right;
  svg.append(svgEl("line", { class: "axis", x1: FIG.left, x2: FIG.left, y1: FIG.top, y2: FIG.h - FIG.bottom }));
  svg.append(svgEl("line", { class: "axis", x1: FIG.left, x2: x1, y1: FIG.h - FIG.bottom, y2: FIG.h - FIG.bottom }));
  for (const v of [y0 + 0.06 / 1.12 * (y1 - y0), (y0 + y1) / 2, y1 - 0.06 / 1.12 * (y1 - y0)]) {
    const t = svgEl("text", { class: "tick", x: FIG.left - 4, y: Y(v) + 4, "text-anchor": "end" });
    t.textContent = Number(v.toPrecision(3)).toString();
    svg.append(t);
  }
  const every = Math.max(1, Math.ceil(msg.maneuvers.length / 8));
  msg.maneuvers.forEach((m, i) => {
    if (i % every) return;
    const t = svgEl("text", { class: "tick", x: X(i), y: FIG.h - FIG.bottom + 14, "text-anchor": "middle" });
    t.textContent = m.name.length > 7 ? m.name.slice(-7) : m.name;
    svg.append(t);
  });
}

// Table 4 live: per parameter (and method) the mean of the estimates, their scatter, the mean
// conventional and corrected standard errors and each over the scatter.
function table4(msg) {
  const table = document.getElementById("table4");
  const body = table.querySelector("tbody");
  body.textContent = "";
  const methods = new Set(msg.table4.map((r) => r.method));
  table.dataset.methods = [...methods].join(",");
  for (const r of msg.table4) {
    const tr = document.createElement("tr");
    tr.dataset.parameter = r.parameter;
    tr.dataset.method = r.method;
    const name = document.createElement("td");
    name.append(typeset(r.parameter) || r.parameter);
    if (methods.size > 1) name.append(" (" + r.method + ")");
    const n = cell("maneuvers", r.maneuvers);
    n.textContent = String(r.maneuvers);
    tr.append(name, n, cell("mean", r.mean, 4), cell("scatter", r.scatter, 3),
              cell("se_conventional", r.se_conventional, 3), cell("se_corrected", r.se_corrected, 3),
              cell("conventional_over_scatter", r.conventional_over_scatter, 3),
              cell("corrected_over_scatter", r.corrected_over_scatter, 3));
    body.append(tr);
  }
}

function maneuverList(msg) {
  const body = document.querySelector("#maneuver-list tbody");
  body.textContent = "";
  for (const m of msg.maneuvers.slice().reverse()) {
    const tr = document.createElement("tr");
    tr.dataset.maneuver = m.name;
    const ok = m.rows.filter((r) => r.status === "ok").length;
    const verdict = cell("verdict", m.verdict || "–");
    verdict.dataset.verdict = (m.verdict || "").split(" (")[0];
    tr.append(cell("name", m.name), cell("duration", m.duration, 3), cell("ok", `${ok} of ${m.rows.length}`), verdict);
    body.append(tr);
  }
}

function drawFlight(msg) {
  flight.message = msg;
  const n = msg.maneuvers.length;
  document.getElementById("flight-count").textContent =
    `${n} maneuver${n === 1 ? "" : "s"}` + (msg.recorded > n ? ` shown of ${msg.recorded} recorded` : "");
  document.getElementById("flight").dataset.maneuvers = String(n);
  document.getElementById("active").textContent = msg.active ? "running: " + msg.active : "between maneuvers";
  table4(msg);
  maneuverList(msg);
  const figs = document.getElementById("fig12");
  figs.textContent = "";
  for (const r of msg.table4) figs.append(figure12(msg, r));
  if (flight.health !== undefined) drawTargets(flight.health); // a maneuver started or ended
}

// The current test point from the node's /diagnostics: per parameter with a target its percent
// error and the time left at the present rate of information (target.<p>), and the verdict.
// With maneuvers, outside a test point the estimator runs over trim: its targets mean nothing
// then, and the card gives the last test point's verdict at its end instead.
function drawTargets(health) {
  flight.health = health;
  const body = document.querySelector("#targets tbody");
  body.textContent = "";
  const v = document.getElementById("verdict");
  const msg = flight.message;
  if (msg && !msg.active) {
    const last = msg.maneuvers[msg.maneuvers.length - 1];
    v.textContent = last ? `between test points: the last, ${last.name}, ended ${last.verdict || "without targets"}`
      : "waiting for the first test point";
    v.dataset.verdict = "between";
    return;
  }
  let verdict = "";
  for (const values of Object.values((health && health.models) || {})) {
    if (values.verdict && !verdict) verdict = values.verdict;
    for (const [k, v] of Object.entries(values)) {
      if (!k.startsWith("target.")) continue;
      const tr = document.createElement("tr");
      tr.dataset.parameter = k.slice(7);
      const name = document.createElement("td");
      name.append(typeset(k.slice(7)) || k.slice(7));
      const text = cell("target", v);
      text.dataset.met = v.startsWith("met") ? "1" : "0";
      tr.append(name, text);
      body.append(tr);
    }
  }
  v.textContent = verdict || "no targets (targets.percent) set";
  v.dataset.verdict = verdict.split(" (")[0];
}

// wavestack live view: one WebSocket, one JSON update per message, drawn into the page.
// Plain JavaScript, no libraries; the page only reads (it sends nothing the server acts on).
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const TREND_STEADY = 1e-3; // waves; smaller changes show as steady (as in the terminal's view)
let lastState = "connecting";

function $(id) { return document.getElementById(id); }

function text(id, value) { $(id).textContent = value; }

function fixed(value, digits) {
  return value === null || value === undefined ? "-" : Number(value).toFixed(digits);
}

function signed(value, digits) {
  if (value === null || value === undefined) return "-";
  const s = Number(value).toFixed(digits);
  return value >= 0 && !s.startsWith("-") ? "+" + s : s;
}

function general(value) {
  if (value === null || value === undefined) return "-";
  return Math.abs(value) >= 1e4 || (value !== 0 && Math.abs(value) < 1e-3)
    ? Number(value).toExponential(3) : Number(value).toPrecision(4);
}

function setState(state, detail) {
  lastState = state;
  const badge = $("state");
  badge.textContent = state;
  badge.className = "state state-" + state.replace(/\s+/g, "-");
  text("detail", detail);
}

function counts(tally, total, perSet) {
  const [all, processed, dropped, pending] = tally;
  return `${total} ${all} = ${processed} processed + ${dropped} dropped + ${pending} pending` +
    (perSet ? ` (sets of ${perSet})` : "");
}

function drawStation(s) {
  text("results", s.results); text("valid", s.valid);
  text("last-index", s.last_index >= 0 ? s.last_index : "-");
  text("rate", fixed(s.results_per_s, 1));
  text("latency-p50", fixed(s.latency_p50_ms, 1)); text("latency-p99", fixed(s.latency_p99_ms, 1));
  $("frames").textContent = counts(s.frames, "acquired", 0);
  $("sets").textContent = counts(s.sets, "assembled", s.frames_per_set);
  text("aperture", s.aperture); text("fitter", s.fitter);
  text("kappa", general(s.kappa));
  text("flips", s.flips === null ? "-" : s.flips);
  text("max-mu", fixed(s.max_mu, 3));
  text("safety", s.safety === null ? "-" : s.safety);
  text("plc-state", s.plc_state === null ? "-" : s.plc_state);
  text("sent", s.sent === null ? "-" : (s.sent ? "sent" : "not sent") +
       (s.heartbeat_ok === false ? ", heartbeat failed" : ""));
  text("residual-rms", fixed(s.residual_rms, 4)); text("residual-pv", fixed(s.residual_pv, 4));
  text("pv", fixed(s.pv, 4)); text("pvr", fixed(s.pvr, 4));
  text("quality", s.quality === null ? "-" :
       `${s.quality[1]} used of ${s.quality[0]}; left out: low modulation ${s.quality[2]}, saturated ${s.quality[3]}, ` +
       `fringe order ${s.quality[4]}, clipped ${s.quality[5]}, rim ${s.quality[6]}`);
  text("surface", s.surface === null ? "-" :
       `IRR ${fixed(s.surface[0], 2)}, RMSt ${fixed(s.surface[1], 2)}, PVr ${fixed(s.surface[2], 2)} nm`);
  text("spec", s.spec === null ? "-" :
       `${s.spec[0]}: ${s.spec[1] ? "PASS" : "FAIL"} (limiting: ${s.spec[2]})`);
  text("truth-error", fixed(s.truth_error_rms, 4));
  text("last-reason", s.last_reason || "-");
  text("shown-index", s.shown_index >= 0 ? s.shown_index : "-");
  text("ordering", s.ordering);
  drawBars(s.coefficients);
}

function drawBars(coefficients) {
  const box = $("coefficients");
  const scale = Math.max(1e-6, ...coefficients.map(c => Math.abs(c.value || 0)));
  box.replaceChildren();
  for (const c of coefficients) {
    const row = document.createElement("div");
    row.className = "bar-row"; row.dataset.index = c.index; row.dataset.value = c.value;
    const label = document.createElement("span");
    label.className = "bar-label"; label.textContent = `Z${c.index} ${c.name}`;
    const track = document.createElement("div");
    track.className = "bar-track";
    const bar = document.createElement("div");
    const half = 50 * Math.abs(c.value || 0) / scale;
    bar.className = c.value < 0 ? "bar negative" : "bar";
    bar.style.left = (c.value < 0 ? 50 - half : 50) + "%";
    bar.style.width = half + "%";
    track.append(bar);
    const value = document.createElement("span");
    value.className = "bar-value"; value.id = `coef-${c.index}`; value.textContent = signed(c.value, 4);
    const trend = document.createElement("span");
    const steady = Math.abs(c.change || 0) < TREND_STEADY;
    trend.className = steady ? "trend-steady" : (c.change > 0 ? "trend-up" : "trend-down");
    trend.textContent = steady ? "=" : (c.change > 0 ? "\u25b2" : "\u25bc");
    trend.title = `change over the window: ${signed(c.change, 4)} waves`;
    row.append(label, track, value, trend);
    box.append(row);
  }
}

function drawMap(m) {
  const image = $("map-image");
  if (m.png) {
    image.src = m.png;
    image.dataset.seq = m.seq;
    image.dataset.vmin = m.vmin; image.dataset.vmax = m.vmax; image.dataset.title = m.title;
    image.hidden = false; $("map-empty").hidden = true;
    $("scale-bar").style.background = `linear-gradient(to top, ${m.colours.join(", ")})`;
    drawOutline(m);
    text("map-title", m.title);
    text("scale-max", general(m.vmax)); text("scale-min", general(m.vmin)); text("scale-units", m.units);
    text("map-rms", general(m.rms)); text("map-pv", general(m.pv)); text("map-units", m.units);
    text("map-render-ms", fixed(m.render_ms, 1));
    text("map-left-out", m.left_out);
  }
}

function drawOutline(m) {
  const svg = $("map-outline");
  svg.setAttribute("viewBox", `0 0 ${m.width} ${m.height}`);
  svg.replaceChildren();
  for (const polygon of m.outline) {
    const shape = document.createElementNS(SVG, "polygon");
    shape.setAttribute("points", polygon.map(p => p.join(",")).join(" "));
    svg.append(shape);
  }
}

function drawHistory(h) {
  const panel = $("history-panel");
  panel.hidden = false;
  text("history-title", h.kind === "polish" ? "polishing runs" : h.kind === "align" ? "alignment iterations" : "loop");
  text("loop-phase", h.phase || "-"); text("loop-reason", h.reason || "");
  text("trend-label", h.trend_label || "trend");
  text("trend-values", h.trend.length ? h.trend.map(v => general(v)).join(" \u2192 ") : "-");
  drawTrend(h.trend);
  const head = panel.querySelector("thead"), body = panel.querySelector("tbody");
  const headRow = document.createElement("tr");
  for (const c of h.columns) { const th = document.createElement("th"); th.textContent = c; headRow.append(th); }
  head.replaceChildren(headRow);
  body.replaceChildren(...h.rows.map(row => {
    const tr = document.createElement("tr");
    for (const cell of row) {
      const td = document.createElement("td");
      td.textContent = cell === null ? "-" : (typeof cell === "number" && !Number.isInteger(cell) ? general(cell) : cell);
      tr.append(td);
    }
    return tr;
  }));
}

function drawTrend(values) {
  const svg = $("trend");
  svg.replaceChildren();
  if (values.length < 1) return;
  const low = Math.min(...values), high = Math.max(...values), span = high - low || 1;
  const points = values.map((v, k) => [values.length > 1 ? 300 * k / (values.length - 1) : 150,
                                       75 - 70 * (v - low) / span]);
  const line = document.createElementNS(SVG, "polyline");
  line.setAttribute("points", points.map(p => p.join(",")).join(" "));
  svg.append(line);
}

function draw(u) {
  text("title", u.title);
  document.title = `${u.title}: ${u.state}`;
  setState(u.state, u.detail);
  if (u.station) drawStation(u.station);
  if (u.map) drawMap(u.map);
  if (u.history && u.history.columns) drawHistory(u.history);
  text("renders", u.renders); text("render-mean", fixed(u.render_ms_mean, 1));
  text("browser-sent", u.browser.sent); text("browser-dropped", u.browser.dropped);
  text("dropped-all", u.browser.dropped_all); text("clients", u.browser.clients);
  document.body.dataset.seq = u.seq;
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onmessage = event => draw(JSON.parse(event.data));
  ws.onclose = () => {
    if (lastState === "stopped") {
      text("detail", $("detail").textContent + " (the server closed the connection)");
      return;
    }
    setState("disconnected", "connection to the station lost; retrying every 2 s");
    setTimeout(connect, 2000);
  };
}

connect();

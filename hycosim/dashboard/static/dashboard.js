// The dashboard page: a WebSocket feed of snapshots, drawn into the tables and uPlot charts.
"use strict";
const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const state = { selected: (params.get("ports") || "").split(",").filter(Boolean), plots: {}, data: {}, snapshot: null, ws: null,
  ports: [], chosenByUrl: params.has("ports"), guardedShown: false };
window.hycosim = state;  // for the tests and the curious

function fmt(v, digits = 3) { return v === null || v === undefined ? "–" : Number(v).toFixed(digits); }
function text(el, v) { if (el.textContent !== String(v)) el.textContent = v; }

function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  state.ws = ws;
  ws.onopen = () => { state.data = {}; ws.send(JSON.stringify({ select: state.selected })); };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.problems) showProblems(msg.problems);
    if (msg.state) render(msg);
  };
  ws.onclose = () => {  // the dashboard process went, or the link: say so, and try again
    const el = $("state"); el.className = "state connecting"; el.textContent = "dashboard unreachable; retrying…";
    setTimeout(connect, 1000);
  };
}

function showProblems(problems) {
  const box = $("problems"); box.innerHTML = "";
  for (const p of problems) {
    const div = document.createElement("div");
    div.textContent = p.error + (p.closest && p.closest.length ? ` — did you mean ${p.closest.join(", ")}?` : "");
    box.appendChild(div);
  }
}

function render(s) {
  state.snapshot = s;
  text($("project"), s.project); text($("run"), s.run || "");
  const st = $("state"); st.className = `state ${s.state}`;
  text(st, (s.message || s.state) + (s.loading && s.loading.length ? ` (reading ${s.loading.join(", ")}…)` : ""));
  if (s.read_problems && s.read_problems.length) showProblems(s.read_problems);
  text($("step"), s.step); text($("t"), s.t === null ? "–" : fmt(s.t, 3)); text($("rate"), fmt(s.steps_per_s, 0));
  text($("mode"), s.mode || "–"); text($("lateness"), s.lateness_s === null ? "–" : fmt(1000 * s.lateness_s, 1));
  const drops = Object.entries(s.dropped || {});
  text($("dropped"), drops.length ? drops.map(([r, n]) => `${r}: ${n}`).join(", ") : "none");
  const ages = Object.entries(s.ages || {});
  text($("ages"), ages.length ? ages.map(([p, a]) => `${p}: ${fmt(a, 3)}`).join(", ") : "–");
  nodeRows(s.nodes);
  portValues(s.values || {});
  // A finished run opens on the ports its events' guards name, unless the URL chose others.
  if (!state.chosenByUrl && !state.guardedShown && (s.guarded || []).length) {
    state.guardedShown = true;
    select(s.guarded);
  }
  const list = $("switches");
  const items = (s.switches || []).map((e) =>
    `<li>t=${fmt(e.t, 4)} s: <b>${esc(e.event)}</b> ${esc(e.from)} → ${esc(e.to)} <code>${esc(e.guard)}</code> ` +
    `${esc(JSON.stringify(e.values))}</li>`).join("");
  if (list.dataset.html !== items) { list.innerHTML = items; list.dataset.html = items; }
  $("slider").hidden = s.source !== "run";
  scene(s.scene || {});
  state.markers = (s.switches || []).map((e) => e.t);
  for (const [port, part] of Object.entries(s.series)) {
    if (!state.selected.includes(port)) continue;  // taken off the page while this snapshot came
    // Only what this page lacks comes: points after those it has, or all of them anew.
    const held = state.data[port] && part.from > 0 ? state.data[port] : [[], []];
    held[0].push(...part.t); held[1].push(...part.y);
    state.data[port] = held;
    draw(port, held);
  }
}

function nodeRows(nodes) {
  // The rows are made once per set of nodes and their cells' text changed in place after:
  // rebuilding the table five times a second is the page's work the run pays for on a small machine.
  const body = $("nodes").tBodies[0], names = nodes.map((n) => n.name).join("\n");
  if (body.dataset.names !== names) {
    body.innerHTML = nodes.map((n) => `<tr data-node="${esc(n.name)}"><td>${esc(n.name)}</td>` +
      "<td></td><td></td><td></td><td></td><td></td></tr>").join("");
    body.dataset.names = names;
  }
  nodes.forEach((n, i) => {
    const cells = body.rows[i].cells;
    const status = n.status ?? (n.attached === null ? "" : n.lost ? "lost" : n.attached ? "attached" : "not attached");
    const cls = status.replace(" ", "-");
    if (cells[1].className !== cls) cells[1].className = cls;
    text(cells[1], status); text(cells[2], n.host || "");
    text(cells[3], n.held_share === null ? "–" : fmt(100 * n.held_share, 1) + " %");
    text(cells[4], fmt(n.mean_arrival_ms, 3)); text(cells[5], n.restarts ?? "–");
  });
}

const COLOURS = ["#8e5b2e", "#2a62c9", "#27ae60", "#c0392b", "#7f8c8d"];
function scene(nodes) {  // the twin, side view: each node's points joined in order, on a fixed scale
  const names = Object.keys(nodes);
  $("scene-box").hidden = names.length === 0;
  if (!names.length) return;
  const b = state.bounds || (state.bounds = { x0: Infinity, x1: -Infinity, z0: Infinity, z1: -Infinity });
  for (const n of names) for (const [x, z] of nodes[n]) {
    b.x0 = Math.min(b.x0, x); b.x1 = Math.max(b.x1, x); b.z0 = Math.min(b.z0, z); b.z1 = Math.max(b.z1, z);
  }
  const c = $("scene"), ctx = c.getContext("2d"), pad = 30;
  const span = Math.max(b.x1 - b.x0, b.z1 - b.z0, 1e-6);
  const k = Math.min(c.width, c.height) - 2 * pad;
  const px = (x) => pad + (x - b.x0) / span * k, pz = (z) => c.height - pad - (z - b.z0) / span * k;
  ctx.clearRect(0, 0, c.width, c.height);
  names.forEach((n, i) => {
    const pts = nodes[n], colour = COLOURS[i % COLOURS.length];
    ctx.strokeStyle = ctx.fillStyle = colour; ctx.lineWidth = 4;
    ctx.beginPath(); pts.forEach(([x, z], j) => (j ? ctx.lineTo(px(x), pz(z)) : ctx.moveTo(px(x), pz(z)))); ctx.stroke();
    for (const [x, z] of pts) { ctx.beginPath(); ctx.arc(px(x), pz(z), 5, 0, 2 * Math.PI); ctx.fill(); }
    ctx.fillText(n, px(pts[0][0]) + 8, pz(pts[0][1]) - 8);
  });
}

function esc(v) { return String(v).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`); }

// uPlot 1.6.32 (the latest release) takes seconds to lay out an axis whose span is a few parts in
// 10^10 to 10^7 of its values (a series converging: 1.9999999925 … 1.9999999999; uPlot issues
// #1084, #1135), and the page stops meanwhile (up to 8 s, one paced benchmark run in four): such a
// span is drawn as if flat. Otherwise the ranges are uPlot's own (x: the data's; y: padded by a tenth).
const TINY = 1e-6;
const tiny = (min, max) => max - min <= TINY * Math.max(Math.abs(min), Math.abs(max));
const flat = (min, max) => uPlot.rangeNum((min + max) / 2, (min + max) / 2, 0.1, true);
const X_RANGE = (u, min, max) => (min == null ? [null, null] : tiny(min, max) ? flat(min, max) : [min, max]);
const Y_RANGE = (u, min, max) => (min == null ? [null, null] : tiny(min, max) ? flat(min, max) : uPlot.rangeNum(min, max, 0.1, true));

function draw(port, data) {
  let p = state.plots[port];
  if (!p) {
    const box = document.createElement("div"); box.className = "plot"; box.dataset.port = port;
    box.innerHTML = `<h3>${esc(port)} <span class="value"></span></h3>`;
    $("plots").appendChild(box);
    const opts = {
      width: Math.max(400, $("plots").clientWidth - 20), height: 200,
      scales: { x: { time: false, range: X_RANGE }, y: { range: Y_RANGE } }, series: [{ label: "t (s)" }, { label: port, stroke: "#2a62c9", width: 1.5 }],
      hooks: { draw: [(u) => marks(u, state.markers || [])] },
    };
    p = state.plots[port] = { chart: new uPlot(opts, data, box), box, drawn: 0 };
  }
  p.chart.setData(data);
  p.drawn = data[0].length;
  cursorValue(port);
}

function marks(u, times) {  // the mode switches: dashed lines across the plot
  const ctx = u.ctx; ctx.save(); ctx.strokeStyle = "#c0392b"; ctx.setLineDash([4, 4]);
  for (const t of times) {
    const x = u.valToPos(t, "x", true);
    if (x >= u.bbox.left && x <= u.bbox.left + u.bbox.width) {
      ctx.beginPath(); ctx.moveTo(x, u.bbox.top); ctx.lineTo(x, u.bbox.top + u.bbox.height); ctx.stroke();
    }
  }
  ctx.restore();
}

function cursorValue(port) {  // a finished run's time slider: each plot's value at the chosen time
  const p = state.plots[port]; if (!p || state.snapshot?.source !== "run") return;
  const [t, y] = p.chart.data; if (!t.length) return;
  const at = t[0] + (t[t.length - 1] - t[0]) * $("cursor").value / 1000;
  let i = t.findIndex((v) => v >= at); if (i < 0) i = t.length - 1;
  text($("cursor-t"), `t = ${fmt(t[i], 4)} s`);
  text(p.box.querySelector(".value"), `= ${fmt(y[i], 6)}`);
  p.chart.setCursor({ left: p.chart.valToPos(t[i], "x"), top: p.chart.valToPos(y[i] ?? 0, "y") });
}

// The selection: plotted, marked in the port list, kept in the URL (a link shows the same plots).
function select(ports) {
  for (const port of Object.keys(state.plots)) {
    if (!ports.includes(port)) { state.plots[port].chart.destroy(); state.plots[port].box.remove(); delete state.plots[port]; }
  }
  state.selected = [...ports];
  const query = ports.map(encodeURIComponent).join(",");
  history.replaceState(null, "", ports.length ? `?ports=${query}` : location.pathname);
  for (const li of $("portlist").querySelectorAll("li")) li.classList.toggle("on", ports.includes(li.dataset.port));
  if (state.ws && state.ws.readyState === 1) { state.data = {}; state.ws.send(JSON.stringify({ select: state.selected })); }
}

function toggle(port) {
  select(state.selected.includes(port) ? state.selected.filter((p) => p !== port) : [...state.selected, port]);
}

function portList(ports) {  // every port, grouped by node in the run's order
  const groups = new Map();
  for (const p of ports) { const i = p.indexOf("."); const n = p.slice(0, i); (groups.get(n) || groups.set(n, []).get(n)).push(p); }
  $("portlist").innerHTML = [...groups].map(([node, names]) => `<details open data-node="${esc(node)}"><summary>${esc(node)}</summary><ul>` +
    names.map((p) => `<li data-port="${esc(p)}" class="${state.selected.includes(p) ? "on" : ""}"><button type="button">` +
      `${esc(p.slice(node.length + 1))}</button><span class="v"></span></li>`).join("") + "</ul></details>").join("");
  filterPorts();
  if (state.snapshot) portValues(state.snapshot.values || {});
}

function filterPorts() {
  const q = $("filter").value.trim().toLowerCase();
  for (const group of $("portlist").querySelectorAll("details")) {
    let shown = 0;
    for (const li of group.querySelectorAll("li")) {
      const hit = !q || li.dataset.port.toLowerCase().includes(q);
      li.hidden = !hit; shown += hit;
    }
    group.hidden = shown === 0;
  }
}

function shortValue(v) {
  if (v === null || v === undefined) return "–";
  if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toPrecision(6);
  const s = String(v); return s.length > 24 ? s.slice(0, 23) + "…" : s;
}

function portValues(values) {
  for (const li of $("portlist").querySelectorAll("li")) text(li.lastChild, shortValue(values[li.dataset.port]));
}

$("cursor").addEventListener("input", () => state.selected.forEach(cursorValue));
$("filter").addEventListener("input", filterPorts);
$("portlist").addEventListener("click", (ev) => {
  const li = ev.target.closest("li[data-port]");
  if (li) toggle(li.dataset.port);
});

async function loadPorts() {
  try {
    const r = await fetch("/api/ports"); const { ports } = await r.json();
    state.ports = ports;
    portList(ports);
    if (!ports.length) setTimeout(loadPorts, 1000);  // a live run's ports come with the server's first answer
  } catch (e) { setTimeout(loadPorts, 1000); }
}
loadPorts();
connect();

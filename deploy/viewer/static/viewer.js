// The swarm's page: draws the frames the server sends over one WebSocket (/ws).
// Plain JavaScript and a canvas; no build step, nothing fetched from the internet.
// The canvas exposes what it drew, read-only, as data- attributes (robot count, sim time,
// how the run ended, frames and radio deliveries received, samples the live view refused,
// chart points held, whether the run is paused) so that tests can check what a person sees.
"use strict";

const ROW = { id: 0, x: 1, y: 2, theta: 3, phase: 4, targetKind: 5, target: 6, lead: 7,
              leadP: 8, decided: 9, trips: 10, pool: 11 };
const TARGET_SITE = 1, TARGET_SITE_INFERRED = 2, TARGET_NEST = 3;
const LINK_SECONDS = 3.0;

const canvas = document.getElementById("arena");
const context = canvas.getContext("2d");
const tooltip = document.getElementById("tooltip");
let hello = null;     // the run's fixed description
let frame = null;     // the newest frame
let opinion = null;   // the selected robot's whole opinion
let selected = null;  // the selected robot's id
let socket = null;
let framesReceived = 0;
let deliveriesReceived = 0;
let rxTrail = [];     // recent radio deliveries, to draw for a moment: [sender, receiver, time]
// The swarm's curves, one point per world state: [t, decided, entropy, pool size, shares...].
let series = [];
const POINT = { t: 0, decided: 1, entropy: 2, pool: 3, shares: 4 };

function $(id) { return document.getElementById(id); }

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws`);
  $("connection").textContent = "connecting";
  socket.onopen = () => {
    $("connection").textContent = "connected";
    if (selected !== null) send({ op: "select", robot: selected });
  };
  socket.onmessage = (event) => receive(JSON.parse(event.data));
  socket.onclose = () => {
    // The run may be over (the server stops with it) or the server restarting: keep the
    // last picture and try again.
    $("connection").textContent = frame && frame.ended ? "server closed" : "reconnecting…";
    setTimeout(connect, 1000);
  };
}

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
}

function receive(message) {
  if (message.type === "hello") {
    hello = message;
    setUpLegend();
    $("run-id").textContent = message.run_id;
    $("mode").textContent = message.mode === "replay" ? "(replay)" : "(live)";
    canvas.dataset.mode = message.mode;
    $("replay-controls").hidden = message.mode !== "replay";
    series = [];
  } else if (message.type === "frame") {
    frame = message;
    framesReceived += 1;
    deliveriesReceived += message.rx.length;
    const now = performance.now();
    for (const [sender, receiver] of message.rx) rxTrail.push([sender, receiver, now]);
    rxTrail = rxTrail.filter((entry) => now - entry[2] < 400).slice(-3000);
    updateHeader();
    draw();
  } else if (message.type === "opinion") {
    opinion = message;
    drawDetail();
  } else if (message.type === "series") {
    series = message.reset ? message.points : series.concat(message.points);
    $("charts").dataset.points = series.length;
    drawCharts();
  }
}

// --- header and legend -------------------------------------------------------------

function updateHeader() {
  $("sim-time").textContent = frame.t.toFixed(1);
  $("rtf").textContent = frame.rtf === null ? "–" : frame.rtf.toFixed(0);
  $("decided").textContent = `${frame.decided}/${frame.total}`;
  $("trips").textContent = frame.trips;
  for (const name of ["sent", "delivered", "dropped", "rejected"]) {
    $(`radio-${name}`).textContent = frame.radio[name];
  }
  $("ended").textContent = frame.ended ? `ended: ${frame.ended.text}` : "";
  $("links").textContent = describeLinks(frame.links || {});
  const refused = frame.rejected ?? 0;  // the live view's own count (a replay has none)
  $("view-rejected").textContent = refused ? `view refused ${refused}` : "";
  canvas.dataset.robots = frame.robots.length;
  canvas.dataset.simTime = frame.t;
  canvas.dataset.ended = frame.ended ? frame.ended.reason : "";
  canvas.dataset.frames = framesReceived;
  canvas.dataset.deliveries = deliveriesReceived;
  canvas.dataset.rejected = refused;
  canvas.dataset.outside = Object.keys(frame.links || {}).length;
  if (frame.replay) updateReplayControls(frame.replay);
  updateLiveControls(frame.pace);
  canvas.dataset.paused = frame.pace && !frame.pace.playing ? "yes" : "";
}

// Robots outside the emulator: each link's transport, round trip and loss, as the bridge
// last reported them.
function describeLinks(links) {
  return Object.entries(links).map(([robot, link]) => {
    if (!link.connected) return `robot ${robot} (${link.transport}): not connected`;
    const rtt = link.rtt_ms === null ? "–" :
      `${link.rtt_ms.toFixed(1)}/${link.rtt_p95_ms.toFixed(1)} ms`;
    const refused = link.refused ? `, refused ${link.refused}` : "";
    return `robot ${robot} (${link.transport}): rtt ${rtt}, loss ` +
      `${(100 * link.loss).toFixed(0)}%${refused}`;
  }).join("; ");
}

function setUpLegend() {
  const phases = $("phase-legend");
  phases.replaceChildren(...hello.phases.map((phase) => legendItem(phase.colour, phase.label)));
  const sites = $("site-legend");
  sites.replaceChildren(...hello.arena.sites.map((site) => legendItem(
    site.colour,
    `site ${site.id}: ρ = ${site.quality.toFixed(2)}` +
      (site.id === hello.arena.best_site ? " (best)" : ""))));
}

function legendItem(colour, text) {
  const item = document.createElement("li");
  const swatch = document.createElement("span");
  swatch.className = "swatch";
  swatch.style.background = colour;
  item.append(swatch, document.createTextNode(text));
  return item;
}

// --- drawing -------------------------------------------------------------------------

let view = { scale: 1, cx: 0, cy: 0 };

function toScreen(x, y) { return [view.cx + x * view.scale, view.cy - y * view.scale]; }

function resize() {
  const ratio = window.devicePixelRatio || 1;
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(height * ratio);
  }
  context.setTransform(ratio, 0, 0, ratio, 0, 0);
  const radius = hello ? hello.arena.radius : 1;
  view = { scale: Math.min(width, height) / 2 / (radius * 1.18), cx: width / 2, cy: height / 2 };
}

function phaseColour(index) {
  return index >= 0 && hello.phases[index] ? hello.phases[index].colour : "#cccccc";
}

function siteColour(id) {
  const site = hello.arena.sites[id];
  return site ? site.colour : "#999999";
}

function draw() {
  drawCharts();
  resize();
  context.clearRect(0, 0, canvas.clientWidth, canvas.clientHeight);
  if (!hello) return;
  drawArena();
  if (!frame) return;
  const positions = new Map(frame.robots.map((row) => [row[ROW.id], row]));
  if ($("show-targets").checked) drawTargets();
  if ($("show-radio").checked) drawRadio(positions);
  drawPoolings(positions);
  for (const row of frame.robots) drawRobot(row);
}

function drawArena() {
  const arena = hello.arena;
  const [cx, cy] = toScreen(0, 0);
  const r = arena.radius * view.scale;
  context.fillStyle = "#f3f3ef";
  context.beginPath(); context.arc(cx, cy, r, 0, 2 * Math.PI); context.fill();
  context.strokeStyle = "#777"; context.lineWidth = 2; context.stroke();
  // The nest: the beacon's reach.
  context.fillStyle = "rgba(255, 205, 80, 0.35)";
  context.beginPath();
  context.arc(cx, cy, arena.nest.radius * view.scale, 0, 2 * Math.PI);
  context.fill();
  context.setLineDash([4, 4]); context.strokeStyle = "#c9a227"; context.lineWidth = 1;
  context.stroke(); context.setLineDash([]);
  context.fillStyle = "#8a6d00"; context.font = "11px system-ui"; context.textAlign = "center";
  context.fillText("nest", cx, cy + arena.nest.radius * view.scale - 4);
  // Site panels on the wall, in the colour the camera renders, with id and quality.
  for (const site of arena.sites) {
    context.strokeStyle = site.colour;
    context.lineWidth = Math.max(6, 0.04 * view.scale);
    context.beginPath();
    // Canvas angles run clockwise (y down): negate the world's angles.
    context.arc(cx, cy, r, -(site.angle + site.half_width), -(site.angle - site.half_width));
    context.stroke();
    const [lx, ly] = toScreen(1.1 * arena.radius * Math.cos(site.angle),
                              1.1 * arena.radius * Math.sin(site.angle));
    const best = site.id === arena.best_site;
    context.fillStyle = "#222";
    context.font = `${best ? "bold " : ""}12px system-ui`;
    context.fillText(`${site.id}`, lx, ly - 2);
    context.font = "10px system-ui";
    context.fillText(`ρ ${site.quality.toFixed(2)}`, lx, ly + 10);
  }
}

function drawTargets() {
  const arena = hello.arena;
  context.lineWidth = 1;
  for (const row of frame.robots) {
    const kind = row[ROW.targetKind];
    let point = null;
    if (kind === TARGET_NEST) point = [0, 0];
    else if ((kind === TARGET_SITE || kind === TARGET_SITE_INFERRED) && arena.sites[row[ROW.target]]) {
      const site = arena.sites[row[ROW.target]];
      point = [site.x, site.y];
    }
    if (!point) continue;
    const [x1, y1] = toScreen(row[ROW.x], row[ROW.y]);
    const [x2, y2] = toScreen(point[0], point[1]);
    context.strokeStyle = "rgba(0, 0, 0, 0.13)";
    context.setLineDash(kind === TARGET_SITE_INFERRED ? [3, 4] : []);
    context.beginPath(); context.moveTo(x1, y1); context.lineTo(x2, y2); context.stroke();
  }
  context.setLineDash([]);
}

function drawRadio(positions) {
  const now = performance.now();
  context.lineWidth = 1;
  for (const [sender, receiver, when] of rxTrail) {
    const to = positions.get(receiver);
    const from = /^\d+$/.test(sender) ? positions.get(Number(sender)) : [0, 0, 0];
    if (!to || !from) continue;
    const fade = 1 - (now - when) / 400;
    context.strokeStyle = `rgba(30, 100, 220, ${0.35 * fade})`;
    const [x1, y1] = toScreen(from[ROW.x] ?? 0, from[ROW.y] ?? 0);
    const [x2, y2] = toScreen(to[ROW.x], to[ROW.y]);
    context.beginPath(); context.moveTo(x1, y1); context.lineTo(x2, y2); context.stroke();
  }
}

function drawPoolings(positions) {
  for (const [robot, t, , members] of frame.poolings) {
    const centre = positions.get(robot);
    if (!centre) continue;
    const fade = Math.max(0, 1 - (frame.t - t) / LINK_SECONDS);
    const [x1, y1] = toScreen(centre[ROW.x], centre[ROW.y]);
    context.strokeStyle = `rgba(20, 170, 50, ${0.9 * fade})`;
    context.lineWidth = 2.5;
    for (const member of members) {
      const other = positions.get(member);
      if (!other) continue;
      const [x2, y2] = toScreen(other[ROW.x], other[ROW.y]);
      context.beginPath(); context.moveTo(x1, y1); context.lineTo(x2, y2); context.stroke();
    }
    context.fillStyle = `rgba(20, 170, 50, ${0.25 * fade})`;
    context.beginPath();
    context.arc(x1, y1, Math.max(10, 3 * hello.arena.robot_radius * view.scale), 0, 2 * Math.PI);
    context.fill();
  }
}

function robotPixels() { return Math.max(3.5, hello.arena.robot_radius * view.scale); }

function drawRobot(row) {
  const [x, y] = toScreen(row[ROW.x], row[ROW.y]);
  const r = robotPixels();
  context.fillStyle = phaseColour(row[ROW.phase]);
  context.beginPath(); context.arc(x, y, r, 0, 2 * Math.PI); context.fill();
  context.strokeStyle = "#222"; context.lineWidth = 1; context.stroke();
  // Opinion at a glance: an arc in the leading site's colour, as long as its probability.
  if (row[ROW.lead] >= 0) {
    context.strokeStyle = siteColour(row[ROW.lead]);
    context.lineWidth = Math.max(2, r * 0.35);
    context.beginPath();
    context.arc(x, y, r + context.lineWidth, -Math.PI / 2,
                -Math.PI / 2 + 2 * Math.PI * row[ROW.leadP]);
    context.stroke();
  }
  if (row[ROW.decided] >= 0) {  // decided: a full ring in the chosen site's colour
    context.strokeStyle = siteColour(row[ROW.decided]);
    context.lineWidth = 2;
    context.beginPath(); context.arc(x, y, r + 2 * Math.max(2, r * 0.35) + 1, 0, 2 * Math.PI);
    context.stroke();
  }
  // Outside the emulator (hardware in the loop): a square around it, dashed while its
  // link is down.
  const link = (frame.links || {})[String(row[ROW.id])];
  if (link) {
    const side = 2 * (r + 2 * Math.max(2, r * 0.35) + 3);
    context.strokeStyle = "#0d47a1"; context.lineWidth = 1.5;
    context.setLineDash(link.connected ? [] : [3, 3]);
    context.strokeRect(x - side / 2, y - side / 2, side, side);
    context.setLineDash([]);
  }
  // Heading.
  const theta = row[ROW.theta];
  context.strokeStyle = "#111"; context.lineWidth = 1.5;
  context.beginPath(); context.moveTo(x, y);
  context.lineTo(x + 1.5 * r * Math.cos(theta), y - 1.5 * r * Math.sin(theta)); context.stroke();
  if (row[ROW.id] === selected) {
    context.strokeStyle = "#e91e63"; context.lineWidth = 2;
    context.beginPath(); context.arc(x, y, r * 2.6, 0, 2 * Math.PI); context.stroke();
  }
  if (r >= 7) {
    context.fillStyle = "#000"; context.font = "9px system-ui"; context.textAlign = "center";
    context.fillText(String(row[ROW.id]), x, y + 3);
  }
}

// --- hover and selection --------------------------------------------------------------

function robotAt(event) {
  if (!frame || !hello) return null;
  const box = canvas.getBoundingClientRect();
  const px = event.clientX - box.left, py = event.clientY - box.top;
  let best = null, bestDistance = Math.max(8, robotPixels() * 1.5);
  for (const row of frame.robots) {
    const [x, y] = toScreen(row[ROW.x], row[ROW.y]);
    const distance = Math.hypot(px - x, py - y);
    if (distance < bestDistance) { best = row; bestDistance = distance; }
  }
  return best;
}

function describe(row) {
  const phase = row[ROW.phase] >= 0 ? hello.phases[row[ROW.phase]].label : "unknown";
  const decided = row[ROW.decided] >= 0 ? `decided site ${row[ROW.decided]}` : "undecided";
  const link = (frame.links || {})[String(row[ROW.id])];
  const outside = link ? ` (outside, ${link.transport})` : "";
  return `robot ${row[ROW.id]}${outside}: ${phase}\n${decided}\nleads site ${row[ROW.lead]} ` +
    `(p = ${row[ROW.leadP].toFixed(2)})\ntrips ${row[ROW.trips]}, last pool ${row[ROW.pool]}`;
}

canvas.addEventListener("mousemove", (event) => {
  const row = robotAt(event);
  tooltip.hidden = !row;
  if (row) {
    tooltip.textContent = describe(row);
    tooltip.style.left = `${event.clientX + 14}px`;
    tooltip.style.top = `${event.clientY + 10}px`;
  }
});
canvas.addEventListener("mouseleave", () => { tooltip.hidden = true; });
canvas.addEventListener("click", (event) => {
  const row = robotAt(event);
  selected = row ? row[ROW.id] : null;
  opinion = null;
  send({ op: "select", robot: selected });
  drawDetail();
  draw();
});

function drawDetail() {
  const chart = $("opinion");
  const ctx = chart.getContext("2d");
  ctx.clearRect(0, 0, chart.width, chart.height);
  if (selected === null || !frame) {
    $("detail-title").textContent = "robot (click one)";
    $("detail").textContent = "";
    return;
  }
  $("detail-title").textContent = `robot ${selected}`;
  const row = frame.robots.find((r) => r[ROW.id] === selected);
  let text = row ? describe(row) : "";
  if (opinion && opinion.comparison) {
    const c = opinion.comparison;
    text += `\nlast comparison: site ${c.site_a} (${c.quality_a.toFixed(2)}) vs ` +
      `site ${c.site_b} (${c.quality_b.toFixed(2)}), ruled out ${c.eliminated}`;
  }
  $("detail").textContent = text;
  if (!opinion || !opinion.opinion) return;
  const values = opinion.opinion;
  const width = chart.width / values.length;
  values.forEach((p, site) => {
    const height = p * (chart.height - 14);
    ctx.fillStyle = siteColour(site);
    ctx.fillRect(site * width + 1, chart.height - 12 - height, Math.max(1, width - 2), height);
    if (values.length <= 20) {
      ctx.fillStyle = "#333"; ctx.font = "9px system-ui"; ctx.textAlign = "center";
      ctx.fillText(String(site), site * width + width / 2, chart.height - 2);
    }
  });
}

// --- charts ---------------------------------------------------------------------------
// Small line charts of the swarm's curves, drawn up to the sim time shown.

function chartContext(id) {
  const chart = $(id);
  const ratio = window.devicePixelRatio || 1;
  const width = chart.clientWidth, height = chart.clientHeight;
  if (chart.width !== Math.round(width * ratio) || chart.height !== Math.round(height * ratio)) {
    chart.width = Math.round(width * ratio);
    chart.height = Math.round(height * ratio);
  }
  const ctx = chart.getContext("2d");
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.clearRect(0, 0, width, height);
  return { ctx, width, height };
}

// Axes and scales of one chart: x is sim time from 0 to ``tMax``, y from 0 to ``yMax``.
function axes(id, tMax, yMax, yLabel) {
  const c = chartContext(id);
  const left = 30, bottom = 14, top = 4, right = 6;
  const plot = { left, top, width: Math.max(10, c.width - left - right),
                 height: Math.max(10, c.height - top - bottom) };
  const x = (t) => plot.left + plot.width * Math.min(1, t / tMax);
  const y = (v) => plot.top + plot.height * (1 - Math.min(1, Math.max(0, v / yMax)));
  const ctx = c.ctx;
  ctx.strokeStyle = "#999"; ctx.lineWidth = 1;
  ctx.beginPath();
  ctx.moveTo(plot.left, plot.top); ctx.lineTo(plot.left, plot.top + plot.height);
  ctx.lineTo(plot.left + plot.width, plot.top + plot.height); ctx.stroke();
  ctx.fillStyle = "#555"; ctx.font = "10px system-ui";
  ctx.textAlign = "right";
  ctx.fillText(yLabel, plot.left - 3, plot.top + 8);
  ctx.fillText("0", plot.left - 3, plot.top + plot.height);
  ctx.textAlign = "center";
  ctx.fillText(`${tMax.toFixed(0)} s`, plot.left + plot.width - 12, plot.top + plot.height + 12);
  return { ctx, x, y, plot };
}

function line(chart, points, value, colour, width) {
  const { ctx, x, y } = chart;
  ctx.strokeStyle = colour; ctx.lineWidth = width;
  ctx.beginPath();
  let started = false;
  for (const point of points) {
    const v = value(point);
    if (v === null || v === undefined) continue;
    if (started) ctx.lineTo(x(point[POINT.t]), y(v));
    else { ctx.moveTo(x(point[POINT.t]), y(v)); started = true; }
  }
  ctx.stroke();
}

function cursor(chart, t) {
  const { ctx, x, plot } = chart;
  ctx.strokeStyle = "rgba(233, 30, 99, 0.6)"; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(x(t), plot.top); ctx.lineTo(x(t), plot.top + plot.height);
  ctx.stroke();
}

function drawCharts() {
  if (!hello || !frame) return;
  const replay = frame.replay;
  const now = frame.t;
  const shown = series.filter((point) => point[POINT.t] <= now + 1e-6);
  const last = series.length ? series[series.length - 1][POINT.t] : 0;
  const tMax = Math.max(10, replay ? replay.end : Math.max(now, last));
  const decided = axes("chart-decided", tMax, hello.robots, String(hello.robots));
  line(decided, shown, (p) => p[POINT.decided], "#263238", 2);
  const shares = axes("chart-shares", tMax, 1, "1");
  hello.arena.sites.forEach((site) => {
    const best = site.id === hello.arena.best_site;
    line(shares, shown, (p) => p[POINT.shares + site.id], site.colour, best ? 3 : 1.5);
  });
  const bits = Math.log2(Math.max(2, hello.sites));
  const entropy = axes("chart-entropy", tMax, bits, bits.toFixed(1));
  line(entropy, shown, (p) => p[POINT.entropy], "#6a1b9a", 2);
  const sizes = shown.map((p) => p[POINT.pool]).filter((v) => v !== null);
  const poolMax = Math.max(2, ...sizes);
  const pools = axes("chart-pools", tMax, poolMax, String(Math.ceil(poolMax)));
  pools.ctx.fillStyle = "#2e7d32";
  for (const point of shown) {
    if (point[POINT.pool] === null) continue;
    pools.ctx.beginPath();
    pools.ctx.arc(pools.x(point[POINT.t]), pools.y(point[POINT.pool]), 2, 0, 2 * Math.PI);
    pools.ctx.fill();
  }
  if (replay) for (const chart of [decided, shares, entropy, pools]) cursor(chart, now);
}

// --- live controls ----------------------------------------------------------------------
// Pause, play and speed of a lockstep run, for the world (a held run waits at tick 0 for
// the first page).

function updateLiveControls(pace) {
  const live = hello && hello.mode === "live" && pace && pace.can_pace && !frame.ended;
  $("live-controls").hidden = !live;
  if (!live) return;
  $("live-play").textContent = pace.playing ? "pause" : "play";
  const select = $("live-speed");
  if (select.options.length !== pace.speeds.length) {
    select.replaceChildren(...pace.speeds.map((speed) => {
      const option = document.createElement("option");
      option.value = speed === null ? "" : String(speed);
      option.textContent = speed === null ? "as fast as it goes" : `${speed}× real time`;
      return option;
    }));
  }
  select.disabled = pace.speeds.length === 0;
  if (document.activeElement !== select) {
    select.value = pace.speed === null ? "" : String(pace.speed);
  }
  $("live-state").textContent = pace.held ? "held at tick 0" : pace.playing ? "" : "paused";
}

$("live-play").addEventListener("click", () => {
  send({ op: frame && frame.pace && frame.pace.playing ? "pause" : "play" });
});
$("live-speed").addEventListener("change", (event) => {
  const value = event.target.value;
  send({ op: "speed", speed: value === "" ? null : Number(value) });
});

// --- replay controls --------------------------------------------------------------------

let scrubbing = false;

function updateReplayControls(replay) {
  $("play").textContent = replay.playing ? "pause" : "play";
  const timeline = $("timeline");
  timeline.min = replay.start;
  timeline.max = replay.end;
  if (!scrubbing) timeline.value = frame.t;
  $("timeline-label").textContent = `${frame.t.toFixed(1)} / ${replay.end.toFixed(1)} s`;
  if (document.activeElement !== $("speed")) $("speed").value = String(replay.speed);
}

$("play").addEventListener("click", () => {
  send({ op: frame && frame.replay && frame.replay.playing ? "pause" : "play" });
});
$("timeline").addEventListener("input", () => { scrubbing = true; });
$("timeline").addEventListener("change", (event) => {
  scrubbing = false;
  send({ op: "seek", t: Number(event.target.value) });
});
$("speed").addEventListener("change", (event) => {
  send({ op: "speed", speed: Number(event.target.value) });
});
$("next-pooling").addEventListener("click", () => send({ op: "next", kind: "pooling" }));
$("next-decision").addEventListener("click", () => send({ op: "next", kind: "decision" }));
$("show-radio").addEventListener("change", draw);
$("show-targets").addEventListener("change", draw);
window.addEventListener("resize", draw);

connect();

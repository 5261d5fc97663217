// The skymesh web console: polls /api/mesh and /api/vehicles once a second and
// draws them. Everything shown is set with textContent (never HTML): service
// names, autopilot status texts and arbiter details are data, not markup.
"use strict";

const POLL_MS = 1000;
const FETCH_TIMEOUT_MS = 4000;
// An action waits for the arbiter's answer (the supervisor gives up after 8 s).
const ACTION_TIMEOUT_MS = 12000;
const PLOT_SPAN_S = 300;
// Points further apart than this are not joined (nobody was looking meanwhile).
const PLOT_GAP_S = 5;

let actions = false;
let restartAction = false;

const $ = (sel, root = document) => root.querySelector(sel);

function text(el, value) {
  const s = value === null || value === undefined ? "—" : String(value);
  if (el.textContent !== s) el.textContent = s;
}

function fixed(v, digits, unit) {
  return typeof v === "number" ? `${v.toFixed(digits)}${unit}` : null;
}

function duration(s) {
  if (typeof s !== "number") return null;
  if (s < 60) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m} min ${Math.floor(s % 60)} s`;
  const h = Math.floor(m / 60);
  if (h < 48) return `${h} h ${m % 60} min`;
  return `${Math.floor(h / 24)} d ${h % 24} h`;
}

function bytes(n) {
  if (typeof n !== "number") return null;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(0)} KiB`;
  return `${(n / 1024 / 1024).toFixed(1)} MiB`;
}

function message(s, kind) {
  const el = $("#message");
  text(el, s);
  el.className = kind || "";
}

async function getJson(path, init = {}, timeoutMs = FETCH_TIMEOUT_MS) {
  const ctl = new AbortController();
  const timer = setTimeout(() => ctl.abort(), timeoutMs);
  try {
    const r = await fetch(path, { ...init, signal: ctl.signal, cache: "no-store" });
    let body = null;
    try { body = await r.json(); } catch (_) { body = null; }
    return { status: r.status, body };
  } finally {
    clearTimeout(timer);
  }
}

// ---- services -----------------------------------------------------------

function serviceRow(tbody, s) {
  const id = `svc-${s.name}`;
  let tr = document.getElementById(id);
  if (!tr) {
    tr = document.createElement("tr");
    tr.id = id;
    tr.dataset.name = s.name;
    for (const [f, cls] of [["name", ""], ["state", ""], ["pid", ""], ["restarts", "num"],
      ["uptime", "num"], ["heartbeat", "num"], ["cpu", "num"], ["memory", "num"]]) {
      const td = document.createElement("td");
      td.dataset.f = f;
      if (cls) td.className = cls;
      tr.appendChild(td);
    }
    const td = document.createElement("td");
    td.className = "action-col";
    const b = document.createElement("button");
    b.type = "button";
    b.textContent = "Restart";
    b.dataset.restart = s.name;
    b.addEventListener("click", () => restart(s.name));
    td.appendChild(b);
    tr.appendChild(td);
    tbody.appendChild(tr);
  }
  const cell = (f) => $(`[data-f="${f}"]`, tr);
  text(cell("name"), s.critical ? `${s.name} *` : s.name);
  const state = cell("state");
  state.replaceChildren();
  const badge = document.createElement("span");
  badge.className = `badge state-${s.state}`;
  badge.textContent = s.adopted ? `${s.state} (adopted)` : s.state;
  state.appendChild(badge);
  text(cell("pid"), s.pid);
  text(cell("restarts"), s.restarts);
  cell("restarts").dataset.value = s.restarts;
  text(cell("uptime"), s.pid ? duration(s.uptime_s) : null);
  text(cell("heartbeat"), fixed(s.heartbeat_age_s, 1, " s"));
  text(cell("cpu"), fixed(s.cpu_percent, 1, " %"));
  text(cell("memory"), bytes(s.memory_bytes));
  $(".action-col", tr).hidden = !restartAction;
}

function drawMesh(doc) {
  actions = doc.actions;
  restartAction = doc.restart_action;
  text($("#meta"), `v${doc.version} (${doc.git})${doc.monitor_only ? " · monitor-only" : ""} · supervisor up ${duration(doc.supervisor_uptime_s)}`);
  $("#auth").hidden = !actions;
  $("th.action-col").hidden = !restartAction;
  const tbody = $("#services tbody");
  const seen = new Set();
  for (const s of doc.services) {
    serviceRow(tbody, s);
    seen.add(`svc-${s.name}`);
  }
  for (const tr of [...tbody.children]) if (!seen.has(tr.id)) tr.remove();
}

// ---- vehicles -----------------------------------------------------------

function vehicleCard(v) {
  const id = `vehicle-${v.id}`;
  let card = document.getElementById(id);
  if (!card) {
    const empty = $("#vehicles .empty");
    if (empty) empty.remove();
    card = $("#vehicle-template").content.firstElementChild.cloneNode(true);
    card.id = id;
    card.dataset.vehicle = v.id;
    for (const b of card.querySelectorAll("[data-act]")) {
      b.addEventListener("click", () => vehicleAction(v.id, b.dataset.act));
    }
    $("#vehicles").appendChild(card);
  }
  return card;
}

function logList(ol, items, line, refused) {
  ol.replaceChildren();
  if (items.length === 0) {
    const li = document.createElement("li");
    li.className = "none";
    li.textContent = "none yet";
    ol.appendChild(li);
    return;
  }
  for (const it of items) {
    const li = document.createElement("li");
    li.textContent = line(it);
    li.title = li.textContent;
    if (refused && refused(it)) li.className = "refused";
    ol.appendChild(li);
  }
}

function drawVehicle(v) {
  const card = vehicleCard(v);
  const f = (name) => $(`[data-f="${name}"]`, card);
  text(f("id"), v.id);
  const link = f("link");
  text(link, v.link_up ? "link up" : "link down");
  link.className = `badge ${v.link_up ? "link-up" : "link-down"}`;
  const emergency = v.authority && v.authority.emergency;
  f("emergency").hidden = !emergency;
  f("emergency").className = "badge emergency";
  text(f("mode"), v.mode);
  text(f("armed"), v.armed ? "ARMED" : "disarmed");
  text(f("position"), typeof v.lat_deg === "number" ? `${v.lat_deg.toFixed(6)}, ${v.lon_deg.toFixed(6)}` : null);
  const alt = f("alt");
  text(alt, typeof v.alt_rel_m === "number" ? `${v.alt_rel_m.toFixed(1)} m (${v.alt_msl_m.toFixed(1)} m MSL)` : null);
  alt.dataset.value = typeof v.alt_rel_m === "number" ? v.alt_rel_m : "";
  text(f("speed"), fixed(v.ground_speed_mps, 1, " m/s"));
  text(f("climb"), fixed(v.climb_mps, 1, " m/s"));
  const volts = fixed(v.battery_v, 2, " V");
  text(f("battery"), v.battery_pct === null ? volts : `${v.battery_pct} %${volts ? " · " + volts : ""}`);
  text(f("telemetry"), v.telemetry_age_s === null ? "no telemetry yet" : `telemetry ${v.telemetry_age_s.toFixed(1)} s old, status ${fixed(v.status_age_s, 1, " s") || "—"} old`);
  text(f("ekf"), v.ekf_healthy === null ? null : (v.ekf_healthy ? "healthy" : "NOT healthy") + (v.ekf_flags !== null ? ` (flags 0x${v.ekf_flags.toString(16)})` : ""));
  text(f("gps"), v.gps_fix === null ? null : `${v.gps_fix}, ${v.satellites} satellites`);
  const a = v.authority;
  text(f("authority"), a ? `flight: ${a.flight || "nobody"} (${a.flight_change}), payload: ${a.payload || "nobody"}${a.emergency ? ` · stop held by ${a.emergency_sources.join(", ")}` : ""}` : null);
  f("authority").dataset.flight = a && a.flight ? a.flight : "";
  text(f("status_text"), v.status_text);
  $(".actions", card).hidden = !actions;
  logList($(".decisions", card), v.decisions,
    (d) => `${d.age_s.toFixed(1).padStart(6)} s  ${d.source || "?"} ${d.kind} #${d.command_id}: ${d.result}${d.reason !== "none" ? " (" + d.reason + ")" : ""}${d.detail ? " — " + d.detail : ""}`,
    (d) => d.result === "refused");
  logList($(".events", card), v.events,
    (e) => `${e.age_s.toFixed(1).padStart(6)} s  ${e.kind}${e.source ? " [" + e.source + "]" : ""}${e.detail ? " — " + e.detail : ""}`);
  $(".events", card).dataset.kinds = v.events.map((e) => e.kind).join(" ");
  plot($("canvas", card), v.history);
}

// Altitude (left scale) and ground speed (right scale) over the last minutes.
function plot(canvas, history) {
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height;
  const pad = { l: 40, r: 40, t: 10, b: 22 };
  const pw = w - pad.l - pad.r, ph = h - pad.t - pad.b;
  ctx.clearRect(0, 0, w, h);
  canvas.dataset.points = history.length;
  const nice = (v) => {
    const m = Math.max(v, 1);
    const step = Math.pow(10, Math.floor(Math.log10(m)));
    for (const k of [1, 2, 5, 10]) if (k * step >= m) return k * step;
    return 10 * step;
  };
  const altMax = nice(Math.max(0, ...history.map((p) => p[1])));
  const altMin = Math.min(0, ...history.map((p) => p[1]));
  const spdMax = nice(Math.max(0, ...history.map((p) => p[2])));
  const x = (t) => pad.l + pw * (1 + t / PLOT_SPAN_S);
  const yAlt = (a) => pad.t + ph * (1 - (a - altMin) / (altMax - altMin || 1));
  const ySpd = (s) => pad.t + ph * (1 - s / spdMax);
  const style = getComputedStyle(document.documentElement);
  ctx.font = "11px sans-serif";
  ctx.strokeStyle = "#e1e4e8";
  ctx.fillStyle = "#66707c";
  ctx.lineWidth = 1;
  for (let i = 0; i <= 4; i++) {
    const y = pad.t + (ph * i) / 4;
    ctx.beginPath(); ctx.moveTo(pad.l, y); ctx.lineTo(pad.l + pw, y); ctx.stroke();
    ctx.textAlign = "right";
    ctx.fillText((altMax - ((altMax - altMin) * i) / 4).toFixed(altMax - altMin < 10 ? 1 : 0), pad.l - 4, y + 4);
    ctx.textAlign = "left";
    ctx.fillText((spdMax - (spdMax * i) / 4).toFixed(1), pad.l + pw + 4, y + 4);
  }
  ctx.textAlign = "center";
  for (let t = -PLOT_SPAN_S; t <= 0; t += 60) {
    ctx.fillText(t === 0 ? "now" : `${t / 60} min`, x(t), h - 6);
  }
  const line = (color, y, idx) => {
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.beginPath();
    let prev = null;
    for (const p of history) {
      if (p[0] < -PLOT_SPAN_S) continue;
      if (prev === null || p[0] - prev > PLOT_GAP_S) ctx.moveTo(x(p[0]), y(p[idx]));
      else ctx.lineTo(x(p[0]), y(p[idx]));
      prev = p[0];
    }
    ctx.stroke();
  };
  line(style.getPropertyValue("--speed").trim() || "#c2571a", ySpd, 2);
  line(style.getPropertyValue("--alt").trim() || "#1f5fbf", yAlt, 1);
  if (history.length === 0) {
    ctx.fillStyle = "#66707c";
    ctx.textAlign = "center";
    ctx.fillText("no position yet", pad.l + pw / 2, pad.t + ph / 2);
  }
}

function drawVehicles(doc) {
  for (const v of doc.vehicles) drawVehicle(v);
}

// ---- actions ------------------------------------------------------------

function token() {
  return $("#token").value.trim();
}

async function post(path) {
  const t = token();
  if (!t) {
    message("enter the console token first (top right)", "error");
    return null;
  }
  try {
    return await getJson(path, { method: "POST", headers: { Authorization: `Bearer ${t}` } }, ACTION_TIMEOUT_MS);
  } catch (e) {
    message(`no answer from the supervisor: ${e}`, "error");
    return null;
  }
}

async function restart(name) {
  const r = await post(`/api/services/${encodeURIComponent(name)}/restart`);
  if (!r) return;
  if (r.status === 202) message(`restart of ${name} requested`, "ok");
  else message(`restart of ${name} refused: ${r.body ? r.body.error : r.status}`, "error");
  poll();
}

async function vehicleAction(id, act) {
  if (token()) message(`vehicle ${id}: ${act} sent, waiting for the arbiter…`, "");
  const r = await post(`/api/vehicles/${id}/${act}`);
  if (!r) return;
  const b = r.body || {};
  if (r.status === 200) message(`vehicle ${id}: ${b.command} ${b.result}${b.detail ? " — " + b.detail : ""}`, "ok");
  else if (r.status === 202) message(`vehicle ${id}: ${b.command} sent — ${b.detail}`, "error");
  else message(`vehicle ${id}: ${act} refused: ${b.error || b.reason || r.status}${b.detail ? " — " + b.detail : ""}`, "error");
  poll();
}

// ---- polling ------------------------------------------------------------

let timer = null;

async function poll() {
  clearTimeout(timer);
  const conn = $("#conn");
  try {
    const [mesh, vehicles] = await Promise.all([getJson("/api/mesh"), getJson("/api/vehicles")]);
    if (mesh.status !== 200 || vehicles.status !== 200) throw new Error(`HTTP ${mesh.status}/${vehicles.status}`);
    drawMesh(mesh.body);
    drawVehicles(vehicles.body);
    text(conn, "live");
    conn.className = "badge live";
  } catch (e) {
    text(conn, "no answer — retrying");
    conn.className = "badge dead";
  }
  timer = setTimeout(poll, POLL_MS);
}

poll();

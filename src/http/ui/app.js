// drawcal browser page: plain JavaScript, no framework, no build step.
// Every number shown comes from the API as it answered; this script only
// formats it (and draws the accuracy history). The calibration's tables and
// plots are the server's HTML report (GET /calibrations/{id}/report.html);
// the report's warnings come from GET /calibrations/{id}.
"use strict";

const $ = (sel, root) => (root || document).querySelector(sel);
const view = () => $("#view");

function esc(s) {
  return String(s == null ? "" : s).replace(/[&<>"']/g, c =>
    ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c]));
}
function num(v, d) {
  if (v === null || v === undefined) return "-";
  return Number(v).toFixed(d === undefined ? 4 : d);
}
// The API's comma-separated effect list, readable.
function spaced(list) { return String(list || "").split(",").join(", "); }

function td(v) {
  return `<td class="num" data-value="${v == null ? "" : v}">${num(v)}</td>`;
}

class ApiErr extends Error {
  constructor(status, body) {
    super(body && body.message ? body.message : "HTTP " + status);
    this.status = status;
    this.body = body || {};
  }
}

// The API key this tab uses (sessionStorage: gone when the tab closes),
// sent as `Authorization: Bearer` on every call.
const KEY_ITEM = "drawcal_key";
function apiKey() { return sessionStorage.getItem(KEY_ITEM) || ""; }
function authHeaders(extra) {
  const h = Object.assign({}, extra || {});
  if (apiKey()) h["authorization"] = "Bearer " + apiKey();
  return h;
}

// The key form in the header: a key is asked for until one is given; a
// 401 (unknown, expired, revoked) asks again.
function keyBox(message) {
  const box = $("#keybox");
  box.innerHTML = apiKey()
    ? `<span class="muted">API key ${esc(apiKey().slice(0, 12))}…</span> <button id="key-forget">forget key</button>`
    : `<label>API key <input type="password" id="api-key" size="24" autocomplete="off"></label> <button id="key-use">use</button>${message ? ` <span class="error-inline">${esc(message)}</span>` : ""}`;
  const use = $("#key-use"), forget = $("#key-forget");
  if (use) use.onclick = () => { sessionStorage.setItem(KEY_ITEM, $("#api-key").value.trim()); keyBox(); route(); };
  if (forget) forget.onclick = () => { sessionStorage.removeItem(KEY_ITEM); keyBox(); route(); };
}

// A file the API serves, downloaded with the key (a plain link could not
// send it).
async function download(path, name) {
  const r = await fetch(path, {headers: authHeaders()});
  if (!r.ok) throw new ApiErr(r.status, await r.json().catch(() => ({})));
  const a = document.createElement("a");
  a.href = URL.createObjectURL(await r.blob());
  a.download = name;
  a.click();
}

async function api(method, path, body, contentType) {
  const opt = {method, headers: authHeaders()};
  if (body !== undefined) {
    opt.headers["content-type"] = contentType || "application/json";
    opt.body = typeof body === "string" ? body : JSON.stringify(body);
  }
  const r = await fetch(path, opt);
  const ct = r.headers.get("content-type") || "";
  const data = ct.includes("json") ? await r.json() : await r.text();
  if (r.status === 401) {
    sessionStorage.removeItem(KEY_ITEM);
    keyBox(data && data.message);
  }
  if (!r.ok) throw new ApiErr(r.status, typeof data === "object" ? data : {message: data});
  return data;
}

// An API error as the API gives it: code, message, field, row.
// `csv`: the request was a CSV file, whose rows the API counts from the
// first line after the header.
function errorHtml(e, csv) {
  if (!(e instanceof ApiErr)) return `<div class="error">${esc(e.message || e)}</div>`;
  const b = e.body;
  let where = "";
  if (b.row != null) {
    where += ` row <b class="err-row">${esc(b.row)}</b>`;
    if (csv) where += ` (line ${esc(b.row + 1)} of the file, counting the header)`;
  }
  if (b.field != null) where += ` ${csv ? "column" : "field"} <b class="err-field">${esc(b.field)}</b>`;
  return `<div class="error" data-error="${esc(b.error)}">HTTP ${e.status} <b>${esc(b.error || "")}</b>${where ? ":" + where : ""}\n${esc(b.message)}</div>`;
}

function showError(el, e) { el.innerHTML = errorHtml(e); }

// A one-line success message for the next view drawn (after an action
// that redraws the page).
let flash = null;

let timers = [];
function clearTimers() { timers.forEach(clearInterval); timers = []; }

async function route() {
  clearTimers();
  $("#status").textContent = "";
  const h = location.hash.replace(/^#/, "") || "/";
  const parts = h.split("/").filter(Boolean);
  try {
    if (parts.length === 0) await fleetView();
    else if (parts[0] === "setup") await setupView();
    else if (parts[0] === "robot") await robotView(+parts[1]);
    else if (parts[0] === "session") await sessionView(+parts[1]);
    else if (parts[0] === "calibration") await calibrationView(+parts[1]);
    else if (parts[0] === "compensate") await compensateView();
    else view().innerHTML = "<p>No such view.</p>";
  } catch (e) {
    view().innerHTML = errorHtml(e);
  }
}
window.addEventListener("hashchange", route);
window.addEventListener("DOMContentLoaded", () => { keyBox(); route(); });

async function all(path) {
  const sep = path.includes("?") ? "&" : "?";
  return (await api("GET", `${path}${sep}limit=1000`)).items;
}

// ---- fleet -------------------------------------------------------------

async function fleetView() {
  const [robots, cals] = await Promise.all([all("/robots"), all("/calibrations")]);
  const byId = new Map(cals.map(c => [c.id, c]));
  let rows = robots.map(r => {
    const c = r.active_calibration_id != null ? byId.get(r.active_calibration_id) : null;
    return `<tr data-robot="${r.id}"><td><a href="#/robot/${r.id}">${esc(r.serial_number)}</a></td>
      <td>${esc(r.model_id)}</td><td>${esc(r.site || "")}</td><td>${esc(r.line || "")}</td><td>${esc(r.cell || "")}</td>
      <td>${c ? `<a href="#/calibration/${c.id}">#${c.id} v${c.version}</a>` : '<span class="muted">nominal</span>'}</td>
      ${c ? td(c.test_rms_before_mm) + td(c.test_rms_after_mm) : "<td>-</td><td>-</td>"}
      <td>${c ? esc(spaced(c.effects)) : ""}</td></tr>`;
  }).join("");
  view().innerHTML = `<h2>Fleet</h2>
    <table id="fleet"><tr><th>robot</th><th>model</th><th>site</th><th>line</th><th>cell</th>
    <th>active calibration</th><th>held-out RMS before (mm)</th><th>held-out RMS after (mm)</th><th>effects</th></tr>
    ${rows || '<tr><td colspan="9" class="muted">No robot yet: add a model, a rig and a robot under “Models &amp; rigs”.</td></tr>'}</table>
    <h2>Calibrations</h2>${calTable(cals)}`;
}

function calTable(cals) {
  if (!cals.length) return '<p class="muted">None yet.</p>';
  return `<table class="cals"><tr><th>calibration</th><th>robot</th><th>created</th><th>method</th><th>poses (test)</th>
    <th>held-out RMS before (mm)</th><th>held-out RMS after (mm)</th><th>effects</th><th>active</th></tr>` +
    cals.map(c => `<tr><td><a href="#/calibration/${c.id}">#${c.id} v${c.version}</a></td>
      <td><a href="#/robot/${c.robot_id}">${esc(c.serial_number)}</a></td><td>${esc(c.created_at)}</td><td>${esc(c.method)}</td>
      <td>${c.n_poses} (${c.n_test})</td>${td(c.test_rms_before_mm)}${td(c.test_rms_after_mm)}<td>${esc(spaced(c.effects))}</td>
      <td>${c.active ? "✔" : ""}</td></tr>`).join("") + "</table>";
}

// ---- setup: models, rigs, robots ----------------------------------------

function fileText(input) {
  return new Promise((ok, bad) => {
    const f = input.files[0];
    if (!f) return bad(new Error("choose a file first"));
    const rd = new FileReader();
    rd.onload = () => ok(rd.result);
    rd.onerror = () => bad(rd.error);
    rd.readAsText(f);
  });
}

async function setupView() {
  const [models, rigs] = await Promise.all([all("/models"), all("/rigs")]);
  view().innerHTML = `<h2>Models &amp; rigs</h2><div class="row">
    <fieldset><legend>Robot model (robot.json)</legend><input type="file" id="model-file" accept=".json">
      <button id="model-add">Add model</button><div id="model-msg"></div>
      <table id="models-table"><tr><th>id</th><th>name</th><th>joints</th></tr>${models.map(m =>
        `<tr><td>${m.id}</td><td>${esc(m.name)}</td><td>${m.dof}</td></tr>`).join("")}</table></fieldset>
    <fieldset><legend>Rig (rig.json)</legend><input type="file" id="rig-file" accept=".json">
      <button id="rig-add">Add rig</button><div id="rig-msg"></div>
      <table id="rigs-table"><tr><th>id</th><th>name</th><th>strings</th></tr>${rigs.map(r =>
        `<tr><td>${r.id}</td><td>${esc(r.name)}</td><td>${r.n_strings}</td></tr>`).join("")}</table></fieldset>
    <fieldset><legend>Robot</legend>
      <label>serial <input type="text" id="robot-serial"></label>
      <label>model <select id="robot-model">${models.map(m => `<option value="${m.id}">${m.id}: ${esc(m.name)}</option>`).join("")}</select></label><br>
      <label>site <input type="text" id="robot-site" size="8"></label><label>line <input type="text" id="robot-line" size="6"></label>
      <label>cell <input type="text" id="robot-cell" size="6"></label>
      <button id="robot-add">Add robot</button><div id="robot-msg"></div></fieldset></div>`;
  const upload = (btn, file, path, msg) => $(btn).onclick = async () => {
    try {
      const text = await fileText($(file));
      const r = await api("POST", path, text);
      $(msg).innerHTML = `<div class="ok">added #${r.id}</div>`;
      setTimeout(route, 400);
    } catch (e) { showError($(msg), e); }
  };
  upload("#model-add", "#model-file", "/models", "#model-msg");
  upload("#rig-add", "#rig-file", "/rigs", "#rig-msg");
  $("#robot-add").onclick = async () => {
    const opt = s => ($(s).value.trim() || null);
    try {
      const r = await api("POST", "/robots", {serial_number: $("#robot-serial").value.trim(),
        model_id: +$("#robot-model").value, site: opt("#robot-site"), line: opt("#robot-line"), cell: opt("#robot-cell")});
      location.hash = `#/robot/${r.id}`;
    } catch (e) { showError($("#robot-msg"), e); }
  };
}

// ---- robot: history, sessions, activation ------------------------------

function historySvg(hist) {
  if (!hist.length) return "";
  const W = 560, H = 240, L = 56, R = 12, T = 22, B = 34;
  // Log scale: before (millimetres) and after (hundredths) differ by
  // orders of magnitude, and a linear axis flattens the after line.
  const vals = hist.flatMap(p => [p.test_rms_before_mm, p.test_rms_after_mm]).filter(v => v != null && v > 0);
  const lo = Math.floor(Math.log10(Math.min(...vals, 1)));
  const hi = Math.max(Math.ceil(Math.log10(Math.max(...vals, 1e-9))), lo + 1);
  const x = i => L + (hist.length === 1 ? (W - L - R) / 2 : i * (W - L - R) / (hist.length - 1));
  const y = v => T + (H - T - B) * (1 - (Math.log10(v) - lo) / (hi - lo));
  const line = (key, color) => {
    const pts = hist.map((p, i) => p[key] == null || !(p[key] > 0) ? null : [x(i), y(p[key])]).filter(Boolean);
    return `<polyline fill="none" stroke="${color}" stroke-width="2" points="${pts.map(p => p.join(",")).join(" ")}"/>` +
      pts.map(p => `<circle cx="${p[0]}" cy="${p[1]}" r="3.5" fill="${color}"/>`).join("");
  };
  let grid = "";
  for (let k = lo; k <= hi; k++) {
    const v = Math.pow(10, k);
    grid += `<line x1="${L}" x2="${W - R}" y1="${y(v)}" y2="${y(v)}" stroke="#e4e4e4"/><text x="${L - 4}" y="${y(v) + 4}" text-anchor="end" font-size="11">${v >= 1 ? v.toFixed(0) : v.toFixed(-k)}</text>`;
  }
  const marks = hist.map((p, i) => `<text x="${x(i)}" y="${H - 18}" text-anchor="middle" font-size="11">v${p.version}${p.effects.length ? " ★" : ""}</text>` +
    (p.effects.length ? `<title>${esc(p.effects.join(", "))}</title>` : "")).join("");
  return `<svg id="history-plot" class="plot" viewBox="0 0 ${W} ${H}" width="${W}" height="${H}"><rect x="${L}" y="${T}" width="${W - L - R}" height="${H - T - B}" fill="#fff" stroke="#999"/>
    ${grid}${line("test_rms_before_mm", "#e8a33d")}${line("test_rms_after_mm", "#d62728")}${marks}
    <text x="${L + 4}" y="14" font-size="12"><tspan fill="#e8a33d">■ held-out RMS before</tspan> <tspan fill="#d62728">■ after</tspan> (mm, log scale; ★ physics finding)</text>
    <text x="${W / 2}" y="${H - 3}" text-anchor="middle" font-size="11">calibration version</text></svg>`;
}

async function robotView(id) {
  const [robot, acc, cals, sessions, acts, rigs] = await Promise.all([
    api("GET", `/robots/${id}`), api("GET", `/robots/${id}/accuracy`), all(`/calibrations?robot_id=${id}`),
    all(`/sessions?robot_id=${id}`), api("GET", `/robots/${id}/activations?limit=50`), all("/rigs")]);
  // The rig of this robot's latest session, else the newest rig (most
  // likely the one just added for it).
  const latest = sessions.reduce((a, b) => (a && a.id > b.id ? a : b), null);
  const defaultRig = latest ? latest.rig_id : rigs.reduce((m, r) => Math.max(m, r.id), -1);
  view().innerHTML = `<h2>Robot ${esc(robot.serial_number)}</h2>
    <p>model ${robot.model_id}, site ${esc(robot.site || "-")}, line ${esc(robot.line || "-")}, cell ${esc(robot.cell || "-")};
    active calibration: ${robot.active_calibration_id != null ? `<a href="#/calibration/${robot.active_calibration_id}">#${robot.active_calibration_id}</a>` : "nominal"}</p>
    <h3>Accuracy over time</h3>${historySvg(acc.history)}
    <table id="history"><tr><th>version</th><th>calibration</th><th>created</th><th>held-out RMS before (mm)</th><th>held-out RMS after (mm)</th><th>findings</th><th>active</th></tr>
    ${acc.history.map(p => `<tr><td>v${p.version}</td><td><a href="#/calibration/${p.calibration_id}">#${p.calibration_id}</a></td><td>${esc(p.created_at)}</td>
      ${td(p.test_rms_before_mm)}${td(p.test_rms_after_mm)}<td>${esc(p.effects.join(", "))}</td><td>${p.active ? "✔" : ""}</td></tr>`).join("")}</table>
    <h3>Sessions</h3>
    <table><tr><th>session</th><th>name</th><th>rig</th><th>poses</th><th>created</th></tr>
    ${sessions.map(s => `<tr><td><a href="#/session/${s.id}">#${s.id}</a></td><td>${esc(s.name || "")}</td><td>${s.rig_id}</td><td>${s.n_poses}</td><td>${esc(s.created_at)}</td></tr>`).join("")}</table>
    <fieldset><legend>New session</legend>
      <label>rig <select id="session-rig">${rigs.map(r => `<option value="${r.id}" ${r.id === defaultRig ? "selected" : ""}>${r.id}: ${esc(r.name)} (${r.n_strings ? `${r.n_strings} strings` : "points: tracker, CMM or camera"})</option>`).join("")}</select></label>
      <label>name <input type="text" id="session-name" value="commissioning"></label>
      <button id="session-add">Create session</button><div id="session-msg"></div></fieldset>
    <fieldset><legend>Roll back</legend>
      <label>reason <input type="text" id="rb-reason" size="40"></label> <span class="muted">(recorded under your key's name)</span>
      <button id="rollback">Roll back to the previous calibration</button><div id="rb-msg"></div></fieldset>
    <h3>Activations</h3><table id="activations"><tr><th>when</th><th>action</th><th>active after it</th><th>by</th><th>reason</th></tr>
    ${acts.items.map(a => `<tr><td>${esc(a.created_at)}</td><td>${esc(a.action)}</td><td>${a.calibration_id != null ? "#" + a.calibration_id : "nominal"}</td><td>${esc(a.actor)}</td><td>${esc(a.reason)}</td></tr>`).join("")}</table>`;
  $("#session-add").onclick = async () => {
    try {
      const s = await api("POST", "/sessions", {robot_id: id, rig_id: +$("#session-rig").value, name: $("#session-name").value || null});
      location.hash = `#/session/${s.id}`;
    } catch (e) { showError($("#session-msg"), e); }
  };
  $("#rollback").onclick = async () => {
    try {
      await api("POST", `/robots/${id}/rollback`, {reason: $("#rb-reason").value});
      route();
    } catch (e) { showError($("#rb-msg"), e); }
  };
}

// ---- session: upload, identify, progress, cancel -------------------------

async function sessionView(id) {
  const [s, jobs] = await Promise.all([api("GET", `/sessions/${id}`), all(`/jobs?session_id=${id}`)]);
  view().innerHTML = `<h2>Session #${s.id} ${esc(s.name || "")}</h2>
    <p>robot <a href="#/robot/${s.robot_id}">#${s.robot_id}</a>, rig ${s.rig_id}; <b id="n-poses">${s.n_poses}</b> poses in <span id="n-batches">${s.n_batches}</span> upload(s)</p>
    <fieldset><legend>Upload poses (poses.csv)</legend>
      <div class="drop" id="drop">Drop a poses.csv here, or <input type="file" id="poses-file" accept=".csv,text/csv"></div>
      <button id="upload">Upload</button> <div id="upload-msg"></div></fieldset>
    <fieldset><legend>Identify</legend>
      <label><input type="checkbox" id="opt-robust"> robust loss</label>
      <label><input type="checkbox" id="opt-physics" checked> physics analysis</label>
      <button id="start">Start identification</button> <div id="job-msg"></div>
      <div id="job"></div></fieldset>
    <h3>Jobs</h3><table id="jobs">${jobsRows(jobs)}</table>`;
  let dropped = null;
  const drop = $("#drop");
  drop.ondragover = e => { e.preventDefault(); drop.classList.add("over"); };
  drop.ondragleave = () => drop.classList.remove("over");
  drop.ondrop = e => {
    e.preventDefault(); drop.classList.remove("over");
    dropped = e.dataTransfer.files[0];
    if (dropped) drop.firstChild.textContent = `${dropped.name} ready; `;
  };
  // The last file chosen wins, dropped or picked.
  $("#poses-file").onchange = () => {
    dropped = null;
    drop.firstChild.textContent = "Drop a poses.csv here, or ";
  };
  $("#upload").onclick = async () => {
    const msg = $("#upload-msg");
    const file = dropped || $("#poses-file").files[0];
    try {
      const text = dropped ? await dropped.text() : await fileText($("#poses-file"));
      msg.innerHTML = '<span class="muted">uploading…</span>';
      const r = await api("POST", `/sessions/${id}/poses`, text, "text/csv");
      msg.innerHTML = `<div class="ok" id="upload-ok">${esc(file ? file.name : "the file")}: ${r.added} poses added; the session holds ${r.session.n_poses}.</div>`;
      $("#n-poses").textContent = r.session.n_poses;
      $("#n-batches").textContent = r.session.n_batches;
      $("#job-msg").innerHTML = "";
    } catch (e) {
      // CSV rows count from the first line after the header.
      msg.innerHTML = (file ? `<p>${esc(file.name)}:</p>` : "") + errorHtml(e, true);
    }
  };
  $("#start").onclick = async () => {
    const start = $("#start");
    start.disabled = true; // one click, one job
    try {
      const job = await api("POST", `/sessions/${id}/jobs`, {robust: $("#opt-robust").checked, physics: $("#opt-physics").checked});
      watchJob(job.id, id);
    } catch (e) { start.disabled = false; showError($("#job-msg"), e); }
  };
  const live = jobs.find(j => j.state === "queued" || j.state === "running");
  if (live) watchJob(live.id, id);
}

// The rows of a session's jobs table, as the API lists the jobs.
function jobsRows(jobs) {
  return `<tr><th>job</th><th>state</th><th>stage</th><th>progress</th><th>calibration</th><th>error</th></tr>` +
    jobs.map(j => `<tr><td>#${j.id}</td><td>${esc(j.state)}</td><td>${esc(j.stage || "")}</td><td>${num(j.progress * 100, 0)} %</td>
      <td>${j.calibration_id != null ? `<a href="#/calibration/${j.calibration_id}">#${j.calibration_id}</a>` : ""}</td><td>${esc(j.error || "")}</td></tr>`).join("");
}

// Redraw the jobs table of the session on screen.
async function drawJobs(sessionId) {
  const jobs = await all(`/jobs?session_id=${sessionId}`);
  const table = $("#jobs");
  if (table) table.innerHTML = jobsRows(jobs);
}

function watchJob(jobId, sessionId) {
  const box = $("#job");
  $("#job-msg").innerHTML = "";
  $("#start").disabled = true;
  const draw = j => {
    const done = ["succeeded", "failed", "cancelled"].includes(j.state);
    box.innerHTML = `<p id="job-state" data-state="${esc(j.state)}">job #${j.id}: <b>${esc(j.state)}</b> ${esc(j.stage || "")}
      <progress max="1" value="${j.progress}"></progress> ${num(j.progress * 100, 0)} %
      ${done ? "" : '<button id="cancel">Cancel</button>'}</p>
      ${j.error ? `<div class="error">${esc(j.error)}</div>` : ""}
      ${j.calibration_id != null ? `<p class="ok">Calibration ready: <a id="cal-link" href="#/calibration/${j.calibration_id}">#${j.calibration_id}</a></p>` : ""}`;
    const c = $("#cancel");
    if (c) c.onclick = async () => {
      try { draw(await api("POST", `/jobs/${j.id}/cancel`)); } catch (e) { showError($("#job-msg"), e); }
    };
    return done;
  };
  const finished = () => {
    clearTimers();
    if ($("#start")) $("#start").disabled = false;
    drawJobs(sessionId).catch(e => showError($("#job-msg"), e));
  };
  const poll = async () => {
    try {
      if (draw(await api("GET", `/jobs/${jobId}`))) finished();
    } catch (e) { showError($("#job-msg"), e); finished(); }
  };
  clearTimers();
  poll();
  timers.push(setInterval(poll, 500));
}

// ---- calibration ---------------------------------------------------------

// The report's `warnings` (input that looks wrong but was used, one
// sentence each, as the API wrote them) as a box; nothing when there are
// none.
function warningsHtml(warnings) {
  if (!warnings || !warnings.length) return "";
  return `<div class="warnings" id="cal-warnings" role="alert"><b>Warning: the input looks wrong.</b> It was used as given; check it before trusting or activating this calibration.<ul>${warnings.map(w => `<li>${esc(w)}</li>`).join("")}</ul></div>`;
}

async function calibrationView(id) {
  const out = await api("GET", `/calibrations/${id}`);
  const c = out.calibration;
  view().innerHTML = `<h2>Calibration #${c.id} v${c.version} of <a href="#/robot/${c.robot_id}">${esc(c.serial_number)}</a></h2>
    <p>${esc(c.created_at)}, method ${esc(c.method)}, ${c.n_poses} poses (${c.n_test} held out), session
    <a href="#/session/${c.session_id}">#${c.session_id}</a>; ${c.active ? "<b>active</b>" : "not active"}.
    <a href="#" id="dl-json">report JSON</a> ·
    <a href="#" id="dl-html">report HTML</a></p>
    ${warningsHtml(out.report && out.report.warnings)}
    <fieldset><legend>${c.active ? "Active for the robot" : "Activate for the robot"}</legend>
      <label>reason <input type="text" id="act-reason" size="40"></label> <span class="muted">(recorded under your key's name)</span>
      ${c.active
        ? `<button id="rollback" title="the robot goes back to the calibration that was active before this one (or to nominal)">Roll back from this calibration</button>`
        : `<button id="activate">Activate</button>`}
      <div id="act-msg">${flash ? `<div class="ok" id="act-ok">${esc(flash)}</div>` : ""}</div></fieldset>
    <div id="report"><p class="muted">Loading the report…</p></div>`;
  flash = null;
  $("#dl-json").onclick = e => { e.preventDefault(); download(`/calibrations/${c.id}`, `calibration-${c.id}.json`).catch(err => showError($("#act-msg"), err)); };
  $("#dl-html").onclick = e => { e.preventDefault(); download(`/calibrations/${c.id}/report.html`, `calibration-${c.id}.html`).catch(err => showError($("#act-msg"), err)); };
  const act = $("#activate"), rb = $("#rollback");
  if (act) act.onclick = async () => {
    act.disabled = true;
    try {
      await api("POST", `/robots/${c.robot_id}/activate`, {calibration_id: c.id, reason: $("#act-reason").value});
      flash = `Calibration #${c.id} is now active for ${c.serial_number}.`;
      route();
    } catch (e) { act.disabled = false; showError($("#act-msg"), e); }
  };
  if (rb) rb.onclick = async () => {
    rb.disabled = true;
    try {
      await api("POST", `/robots/${c.robot_id}/rollback`, {reason: $("#act-reason").value});
      const robot = await api("GET", `/robots/${c.robot_id}`);
      flash = `Rolled back: ${c.serial_number} now runs ${robot.active_calibration_id != null ? `calibration #${robot.active_calibration_id}` : "the nominal model (no calibration)"}.`;
      route();
    } catch (e) { rb.disabled = false; showError($("#act-msg"), e); }
  };
  const t0 = performance.now();
  const html = await api("GET", `/calibrations/${id}/report.html`);
  const doc = new DOMParser().parseFromString(html, "text/html");
  const frag = doc.querySelector(".drawcal-report");
  // The report's own copy of the warnings box: already shown at the top of
  // the view, above activation.
  if ($("#cal-warnings")) { const w = $("#report-warnings", frag); if (w) w.remove(); }
  const box = $("#report");
  box.innerHTML = "";
  box.appendChild(document.adoptNode(frag));
  // After the next frame is painted: the time from asking for the report,
  // and from the page's navigation start.
  requestAnimationFrame(() => setTimeout(() => {
    box.dataset.drawMs = (performance.now() - t0).toFixed(0);
    box.dataset.pageMs = performance.now().toFixed(0);
    $("#status").textContent = `report drawn in ${box.dataset.drawMs} ms`;
  }, 0));
}

// ---- compensate ------------------------------------------------------------

// targets.csv rows to API targets: joint targets (q1_deg...) or Cartesian
// (x_mm, y_mm, z_mm[, roll_deg, pitch_deg, yaw_deg]). Values are passed as
// read.
function parseTargets(text) {
  const lines = text.split(/\r?\n/).filter(l => l.trim() && !l.startsWith("#"));
  if (lines.length < 2) throw new Error("give a header line and at least one target");
  const head = lines[0].split(",").map(s => s.trim());
  const col = n => head.indexOf(n);
  const qs = head.map((h, i) => [h, i]).filter(([h]) => /^q\d+_deg$/.test(h))
    .sort((a, b) => parseInt(a[0].slice(1)) - parseInt(b[0].slice(1))).map(([, i]) => i);
  if (col("target") < 0) throw new Error("targets.csv needs a 'target' column");
  return lines.slice(1).map((l, k) => {
    const c = l.split(",").map(s => s.trim());
    const t = {target: c[col("target")]};
    const n = i => {
      const v = Number(c[i]);
      if (c[i] === undefined || c[i] === "" || !isFinite(v)) throw new Error(`row ${k + 1}: column ${head[i]} is not a number`);
      return v;
    };
    if (qs.length) t.q_deg = qs.map(n);
    else if (col("x_mm") >= 0) {
      t.xyz_mm = ["x_mm", "y_mm", "z_mm"].map(h => n(col(h)));
      if (col("roll_deg") >= 0) t.rpy_deg = ["roll_deg", "pitch_deg", "yaw_deg"].map(h => n(col(h)));
    } else throw new Error("targets.csv needs q1_deg... or x_mm, y_mm, z_mm columns");
    return t;
  });
}

// The run-time conditions POST /compensate takes. Each is used only when
// the calibration accepted the effect that needs it; the answer says which
// were used (temp_c_used, payload_kg_used, approach_used; null when the
// condition does not matter for that calibration) and the page shows that,
// never its own guess.
const APPROACH_TEXT = {positive: "in +q", negative: "in −q", in_order: "in order"};

// Which conditions the selected calibration's findings make relevant, from
// the report as GET /calibrations/{id} gave it: thermal_expansion driven by
// the temperature → temperature, joint_compliance and every other effect
// whose finding says a payload matters (a base tilt, a bending link, a
// compliant tool) → payload, backlash → approach. Only a hint: the inputs stay usable either
// way.
function conditionHints(report) {
  const f = (report && report.findings) || [];
  const of = effect => f.filter(x => x.effect === effect);
  const param = (list, key) => { const x = list.find(x => x.parameters && x.parameters[key] != null); return x ? x.parameters[key] : null; };
  const joints = list => { const j = list.map(x => x.joint).filter(j => j != null); return j.length ? ` of joint ${j.join(", ")}` : ""; };
  const thermal = of("thermal_expansion");
  const byTemp = thermal.filter(x => x.parameters && x.parameters.driver === "temperature");
  // A compliance takes a payload only when compensation says so (its
  // `payload_matters`, from the engine; reports before it: assume it does).
  const loaded = f.filter(x => x.effect !== "joint_compliance" && x.parameters && x.parameters.payload_matters === true);
  const compliance = of("joint_compliance").filter(x => !x.parameters || x.parameters.payload_matters !== false);
  const massFree = of("joint_compliance").length > compliance.length;
  const payloadBy = [...compliance, ...loaded];
  const backlash = of("backlash");
  const refT = param(byTemp, "reference_temp_c"), refP = param(payloadBy, "reference_payload_kg");
  return {
    temp: byTemp.length
      ? {relevant: true, text: `matters: thermal expansion driven by the temperature; default: ${refT != null ? `the reference ${esc(refT)} °C` : "the calibration's reference temperature"}`}
      : {relevant: false, text: thermal.length
        ? `not used: this calibration's thermal expansion is driven by ${esc(thermal.map(x => x.parameters && x.parameters.driver).filter(Boolean).join(", ") || "something other than the temperature")}, which compensation leaves out`
        : "no thermal expansion driven by the temperature among the findings"},
    payload: payloadBy.length
      ? {relevant: true, text: `matters: ${[compliance.length ? `joint compliance${joints(compliance)}` : "", ...loaded.map(x => x.effect.replace("_", " "))].filter(Boolean).map(esc).join(", ")}; default: ${refP != null ? `the session's ${esc(refP)} kg` : "0 kg (the session recorded no payload)"}`}
      : {relevant: false, text: massFree
        ? "not used: this calibration's joint compliance was fitted without link masses and without payload changes, so a payload cannot be applied to it"
        : "no joint compliance, base tilt, bending link or compliant tool among the findings"},
    approach: backlash.length
      ? {relevant: true, text: `matters: backlash${joints(backlash)}; default: every joint moving in +q`}
      : {relevant: false, text: "no backlash among the findings"},
  };
}

// The conditions the answer says were used, as it gave them; `req` only
// says which ones this page sent (a condition used but not sent is the
// calibration's default).
function usedHtml(r, req) {
  const conds = [
    {key: "temp", sent: req.temp_c, used: r.temp_c_used, name: "temperature",
      show: v => `${esc(v)} °C`, given: v => `${esc(v)} °C`, dflt: "the calibration's reference temperature"},
    {key: "payload", sent: req.payload_kg, used: r.payload_kg_used, name: "payload",
      show: v => `payload ${esc(v)} kg`, given: v => `${esc(v)} kg`, dflt: "the calibration session's payload"},
    {key: "approach", sent: req.approach, used: r.approach_used, name: "approach",
      show: v => `joints arriving ${esc(APPROACH_TEXT[v] || v)}`, given: v => esc(v), dflt: "every joint moving in +q"},
  ];
  const span = (c, text) => `<span id="comp-used-${c.key}" data-value="${c.used == null ? "" : esc(c.used)}" data-sent="${c.sent == null ? "" : esc(c.sent)}">${text}</span>`;
  const used = conds.filter(c => c.used != null)
    .map(c => span(c, c.show(c.used) + (c.sent == null ? ` (none given: ${c.dflt})` : "")));
  const unused = conds.filter(c => c.used == null)
    .map(c => span(c, c.name + (c.sent == null ? "" : ` (${c.given(c.sent)} given)`)));
  return `<p id="comp-used">${used.length ? `Compensated for ${used.join(", ")}.` : "Compensated without run-time conditions."}` +
    (unused.length ? ` <span class="muted">Not used by this calibration (it does not depend on ${unused.length > 1 ? "them" : "it"}): ${unused.join(", ")}.</span>` : "") + "</p>";
}

async function compensateView() {
  const robots = await all("/robots");
  const cond = (key, label, input, unit) => `<div class="cond" id="comp-cond-${key}" data-relevant="">
      <label>${label} ${input}${unit}</label> <small class="cond-hint" id="comp-hint-${key}"></small></div>`;
  view().innerHTML = `<h2>Compensate targets</h2>
    <fieldset><legend>Targets (targets.csv)</legend>
      <label>robot <select id="comp-robot">${robots.map(r => `<option value="${r.id}">${esc(r.serial_number)}${r.active_calibration_id != null ? " (calibration #" + r.active_calibration_id + ")" : " (no active calibration)"}</option>`).join("")}</select></label>
      <label>calibration id (default: active) <input type="text" id="comp-cal" size="5"></label>
      <label><input type="checkbox" id="comp-orient"> hold orientation</label><br>
      <textarea id="comp-targets" rows="8">target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg
t1,10,-20,30,0,40,0</textarea><br>
      or load a file <input type="file" id="comp-file" accept=".csv">
      <fieldset id="comp-conditions"><legend>Run-time conditions (optional: sent only when filled in)</legend>
        <div id="comp-cal-info" class="muted"></div>
        ${cond("temp", "temperature", '<input type="text" id="comp-temp" size="11" inputmode="decimal" placeholder="-50 to 150">', " °C")}
        ${cond("payload", "payload at T", '<input type="text" id="comp-payload" size="11" inputmode="decimal" placeholder="0 to 5000">', " kg")}
        ${cond("approach", "joints arrive", `<select id="comp-approach"><option value="">default (not sent)</option>
          <option value="positive">positive: every joint moving in +q</option><option value="negative">negative: every joint moving in −q</option>
          <option value="in_order">in order: each joint from the previous target</option></select>`, "")}
      </fieldset>
      <button id="comp-run">Compensate</button>
      <div id="comp-msg"></div></fieldset><div id="comp-out"></div>`;
  $("#comp-file").onchange = async () => { $("#comp-targets").value = await fileText($("#comp-file")); };

  // The selected calibration's findings say which conditions matter.
  let asked = 0, debounce = null;
  const hints = async () => {
    const ask = ++asked;
    const robot = robots.find(r => r.id === +$("#comp-robot").value);
    const typed = $("#comp-cal").value.trim();
    const calId = typed ? +typed : robot ? robot.active_calibration_id : null;
    const info = $("#comp-cal-info");
    const show = (h, text) => {
      if (ask !== asked) return;
      info.innerHTML = text;
      for (const key of ["temp", "payload", "approach"]) {
        $(`#comp-cond-${key}`).dataset.relevant = h ? String(h[key].relevant) : "";
        $(`#comp-hint-${key}`).innerHTML = h ? h[key].text : "";
      }
    };
    if (calId == null || !Number.isInteger(calId) || calId < 1) {
      show(null, typed ? "no calibration selected: the calibration id is not a number" : "the robot has no active calibration: name one to see which conditions matter");
      return;
    }
    try {
      const out = await api("GET", `/calibrations/${calId}`);
      show(conditionHints(out.report), `which conditions matter, from calibration <a href="#/calibration/${calId}">#${calId}</a>'s findings:`);
    } catch (e) {
      show(null, `no findings to go by (calibration #${calId}: ${esc(e.message)}); the conditions are sent anyway when filled in`);
    }
  };
  $("#comp-robot").onchange = hints;
  $("#comp-cal").oninput = () => { clearTimeout(debounce); debounce = setTimeout(hints, 300); };
  hints();

  $("#comp-run").onclick = async () => {
    const msg = $("#comp-msg");
    msg.innerHTML = "";
    $("#comp-out").innerHTML = "";
    // A condition filled in must be a number; its range is the API's to check.
    const condition = (sel, name) => {
      const s = $(sel).value.trim();
      if (s === "") return undefined;
      const v = Number(s);
      if (!isFinite(v)) throw new Error(`${name}: '${s}' is not a number`);
      return v;
    };
    try {
      const req = {robot_id: +$("#comp-robot").value, orientation: $("#comp-orient").checked,
        targets: parseTargets($("#comp-targets").value)};
      if ($("#comp-cal").value.trim()) req.calibration_id = +$("#comp-cal").value;
      const temp = condition("#comp-temp", "temperature");
      if (temp !== undefined) req.temp_c = temp;
      const payload = condition("#comp-payload", "payload");
      if (payload !== undefined) req.payload_kg = payload;
      if ($("#comp-approach").value) req.approach = $("#comp-approach").value;
      const r = await api("POST", "/compensate", req);
      // compensated.csv as the API writes it (the same writer as the CLI),
      // from the calibration that gave the summary above.
      const csvReq = await fetch("/compensate", {method: "POST",
        headers: authHeaders({"content-type": "application/json", "accept": "text/csv"}),
        body: JSON.stringify({...req, calibration_id: r.calibration_id})});
      const csv = await csvReq.text();
      if (!csvReq.ok) throw new ApiErr(csvReq.status, JSON.parse(csv));
      const url = URL.createObjectURL(new Blob([csv], {type: "text/csv"}));
      $("#comp-out").innerHTML = `<p>calibration #${r.calibration_id} v${r.version}: ${r.n_ok} of ${r.results.length} ok.
        <a id="comp-download" href="${url}" download="compensated.csv">Download compensated.csv</a></p>
        ${usedHtml(r, req)}
        ${(r.warnings || []).length ? `<div class="warnings" id="comp-warnings"><b>Warning</b><ul>${r.warnings.map(w => `<li>${esc(w)}</li>`).join("")}</ul></div>` : ""}
        ${(r.notes || []).length ? `<ul class="muted" id="comp-notes">${r.notes.map(n => `<li>${esc(n)}</li>`).join("")}</ul>` : ""}
        <textarea id="comp-csv" rows="8" readonly>${esc(csv)}</textarea>`;
    } catch (e) { showError(msg, e); }
  };
}

// The fleet page (/) and a run's page (/run/ID), kept live by the feed
// (/events). The page never reloads: the feed says what changed and the
// page fetches what it shows from /api.
"use strict";

const main = document.getElementById("main");
const link = document.getElementById("link");
const fleetLine = document.getElementById("fleet-line");
const runId = location.pathname.startsWith("/run/")
  ? decodeURIComponent(location.pathname.slice(5)) : null;
window.naofarmLoaded = Date.now() + Math.random();

function esc(s) {
  return String(s).replace(/[&<>"]/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"}[c]));
}
function num(v, d) { return v === null || v === undefined ? "–" : Number(v).toFixed(d); }
function pct(v) { return v === null || v === undefined ? "–" : (100 * v).toFixed(0) + " %"; }
function el(html) { const t = document.createElement("template"); t.innerHTML = html.trim(); return t.content.firstChild; }

function setLink(state, text) { link.dataset.state = state; link.textContent = text; }

// ---- the fleet -------------------------------------------------------------

function fleetPage(f) {
  const banner = f.connected ? "" :
    `<div class="banner" id="gone">The fleet does not answer: no router or coordinator is reachable. ` +
    `What it last said is shown; the page catches up when it returns.</div>`;
  const runs = f.runs.map(r => `<tr data-run="${esc(r.id)}" data-state="${esc(r.state)}">
      <td class="l"><a href="/run/${encodeURIComponent(r.id)}">${esc(r.run)}</a></td>
      <td class="l muted">${esc(r.id.slice(0, 8))}</td>
      <td class="l">${esc(r.state)}</td><td>${r.priority}</td>
      <td>${r.decided} / ${r.planned}</td>
      <td>${r.accepts} / ${r.equivalents} / ${r.rejects}</td>
      <td>${num(r.best_mx, 3)}</td><td>${num(r.best_s, 2)}</td>
      <td>${num(r.trials_per_s, 1)}</td><td>${r.in_flight}</td>
      <td>${pct(r.share)}</td><td>${pct(r.fair_share)}</td></tr>`).join("");
  const workers = f.workers.map(w => `<tr data-worker="${esc(w.worker)}">
      <td class="l muted">${esc(w.worker.slice(0, 8))}</td><td class="l">${esc(w.host)}</td>
      <td>${w.busy} / ${w.slots}</td><td class="l muted">${esc(w.fingerprint)}</td>
      <td class="l">${w.programs.map(esc).join(", ") || "–"}</td>
      <td class="l">${w.runs.map(r => esc(r.run) + " (" + r.held + ")").join(", ") || "–"}</td>
      <td>${w.trials}</td><td>${w.refused}</td><td>${num(w.heard_s_ago, 1)} s</td></tr>`).join("");
  main.innerHTML = banner + `
    <h2>Runs</h2>
    <table id="runs"><thead><tr><th class="l">run</th><th class="l">id</th><th class="l">state</th>
      <th>priority</th><th>decided</th><th>A / E / R</th><th>best mx (m)</th><th>s</th>
      <th>trials/s</th><th>in flight</th><th>share</th><th>by priority</th></tr></thead>
      <tbody>${runs || '<tr><td class="l muted" colspan="12">no run answers</td></tr>'}</tbody></table>
    <h2>Workers</h2>
    <table id="workers"><thead><tr><th class="l">worker</th><th class="l">host</th><th>busy</th>
      <th class="l">fingerprint</th><th class="l">programs</th><th class="l">serving</th><th>trials</th>
      <th>failed</th><th>last heard</th></tr></thead>
      <tbody>${workers || '<tr><td class="l muted" colspan="9">no worker answers</td></tr>'}</tbody></table>`;
}

function fleetLineText(f) {
  return `${f.runs.length} runs · ${f.workers.length} workers · ${f.busy} / ${f.slots} slots busy` +
    (f.utilisation === null ? "" : ` (${pct(f.utilisation)})`);
}

// ---- a run -----------------------------------------------------------------

let shown = {decided: -1, state: null, gone: null};
let drawing = false, again = false, tableAsked = false;

function runSkeleton() {
  main.innerHTML = `<div id="run-banner"></div><h2 id="run-title"></h2><div id="run-facts"></div>
    <div id="controls" class="controls"></div>
    <h2>Figures</h2><div id="figures" class="figures"></div>
    <h2>Last decisions</h2><div id="last"></div>
    <h2>Failures and refusals</h2><div id="problems"></div>
    <div id="report"></div>`;
}

async function getJson(url) {
  const r = await fetch(url, {cache: "no-store"});
  if (!r.ok) throw new Error(url + ": " + r.status + " " + (await r.text()));
  return r.json();
}

async function drawRun() {
  if (drawing) { again = true; return; }
  drawing = true;
  try {
    do {
      again = false;
      const run = await getJson("/api/run/" + encodeURIComponent(runId));
      showRun(run);
      await showFigures(run);
    } while (again);
  } catch (e) {
    document.getElementById("run-banner").innerHTML = `<div class="banner">${esc(e.message)}</div>`;
  } finally {
    drawing = false;
  }
}

function reasons(list) {
  return list.length ? `<table><tbody>${list.map(([r, n]) =>
    `<tr><td>${n}</td><td class="l">${esc(r)}</td></tr>`).join("")}</tbody></table>` : '<span class="muted">none</span>';
}

function showRun(run) {
  const s = run.status;
  document.title = "naofarm · " + s.run;
  document.getElementById("run-title").textContent = `${s.run} (${s.id})`;
  const best = s.best ? `ν′ (Optim.1): iteration ${s.best.iteration}, mx ${num(s.best.stats.mx, 3)} m, s ${num(s.best.stats.s, 2)}` : "no ν′ yet";
  document.getElementById("run-facts").innerHTML =
    `<p><span id="run-state">${esc(run.gone && !s.finished ? "gone" : s.state)}</span> · priority ${s.priority} ·
     <span id="run-decided">${s.decided}</span> / ${s.planned} decided · ACCEPT ${s.accepts}, EQUIVALENT ${s.equivalents},
     REJECT ${s.rejects} · ${num(s.trials_per_s, 1)} trials/s · ${s.workers} workers<br>${best}<br>
     Optim.2 (CLOP's mean, at ${s.optim2_decided} decided): ${s.optim2.map(([n, v]) => esc(n) + " = " + num(v, 4)).join(", ") || "–"}</p>`;
  const controls = document.getElementById("controls");
  if (run.control && !s.finished && !run.gone) {
    if (!controls.dataset.built) {
      controls.dataset.built = "1";
      controls.innerHTML = `<button data-action="pause">pause</button><button data-action="resume">resume</button>
        <button data-action="stop">stop</button> priority <input id="priority" type="number" min="1" max="1000" size="5">
        <button data-action="priority">set</button> <span id="control-said" class="muted"></span>`;
      controls.querySelectorAll("button").forEach(b => b.addEventListener("click", () => control(b.dataset.action)));
    }
  } else {
    controls.innerHTML = "";
    delete controls.dataset.built;
  }
  document.getElementById("last").innerHTML = `<table id="decisions"><thead><tr><th>iteration</th><th class="l">decision</th>
    <th>s</th><th>mx (m)</th><th>my (m)</th><th>ex (m)</th><th class="l">parameters</th></tr></thead><tbody>${
    run.last.map(r => `<tr><td>${r.iteration}</td><td class="l">${r.decision}</td><td>${num(r.stats.s, 2)}</td>
      <td>${num(r.stats.mx, 3)}</td><td>${num(r.stats.my, 3)}</td><td>${num(r.stats.ex, 3)}</td>
      <td class="l">${r.params.map(([n, v]) => esc(n) + " " + num(v, 4)).join(", ")}</td></tr>`).join("")}</tbody></table>`;
  document.getElementById("problems").innerHTML =
    `<p>Trials failed or given back:</p>${reasons(s.failures || [])}<p>Messages refused:</p>${reasons(s.refused || [])}`;
  if (s.finished && !tableAsked) { tableAsked = true; showReport(run); }
}

async function showFigures(run) {
  const box = document.getElementById("figures");
  for (const name of run.figures) {
    let fig = box.querySelector(`[data-figure="${name}"]`);
    if (!fig) {
      fig = el(`<div class="figure" data-figure="${esc(name)}"></div>`);
      box.appendChild(fig);
    }
    const r = await fetch(`/api/run/${encodeURIComponent(runId)}/figure/${encodeURIComponent(name)}`, {cache: "no-store"});
    if (r.ok) {
      fig.innerHTML = await r.text();
      fig.dataset.points = fig.querySelectorAll("circle").length;
    }
  }
  box.dataset.decided = run.known;
}

async function showReport(run) {
  const box = document.getElementById("report");
  box.innerHTML = `<h2>Table IV</h2><p id="table" class="muted">running Table IV's trials…</p>`;
  for (;;) {
    let t;
    try { t = await getJson(`/api/run/${encodeURIComponent(runId)}/table`); }
    catch (e) { document.getElementById("table").textContent = e.message; return; }
    if (t.state === "ready") { document.getElementById("table").outerHTML = markdownTable(t.markdown); break; }
    if (t.state === "failed") { document.getElementById("table").textContent = t.why; return; }
    await new Promise(ok => setTimeout(ok, 1500));
  }
  if (run.model === "nao") {
    box.insertAdjacentHTML("beforeend", `<h2>The walks (trial seed 777)</h2><div id="walks" class="figures"></div>`);
    for (const set of ["expert", "optim1", "optim2"]) {
      const url = `/api/run/${encodeURIComponent(runId)}/walk/${set}.svg`;
      for (;;) {
        const r = await fetch(url, {cache: "no-store"});
        if (r.status === 202) { await new Promise(ok => setTimeout(ok, 1000)); continue; }
        if (r.ok) document.getElementById("walks").insertAdjacentHTML("beforeend",
          `<div class="walk"><img alt="${set}" src="${url}"></div>`);
        break;
      }
    }
  }
}

// The report's Markdown table as an HTML table (a caption line, then rows).
function markdownTable(md) {
  const lines = md.split("\n");
  const caption = lines.find(l => l.trim() && !l.startsWith("|")) || "";
  const rows = lines.filter(l => l.startsWith("|") && !/^\|[-| ]+\|?$/.test(l))
    .map(l => l.split("|").slice(1, -1).map(c => c.trim()));
  if (!rows.length) return `<pre>${esc(md)}</pre>`;
  const [head, ...body] = rows;
  return `<table id="table4"><caption class="muted">${esc(caption)}</caption><thead><tr>${
    head.map(c => `<th class="l">${esc(c)}</th>`).join("")}</tr></thead><tbody>${
    body.map(r => `<tr>${r.map((c, i) => `<td class="${i ? "" : "l"}">${esc(c)}</td>`).join("")}</tr>`).join("")}</tbody></table>`;
}

async function control(action) {
  const body = {action};
  if (action === "priority") body.priority = Number(document.getElementById("priority").value);
  const said = document.getElementById("control-said");
  const r = await fetch(`/api/run/${encodeURIComponent(runId)}/control`, {
    method: "POST", headers: {"content-type": "application/json", "x-naofarm": "control"},
    body: JSON.stringify(body)});
  said.textContent = r.ok ? action + ": done" : action + ": " + await r.text();
  drawRun();
}

// ---- the feed ----------------------------------------------------------------

function onFleet(f) {
  fleetLine.textContent = fleetLineText(f);
  if (f.connected) setLink("up", "live");
  else setLink("down", "the fleet does not answer");
  if (!runId) { fleetPage(f); return; }
  const r = f.runs.find(x => x.id === runId);
  const banner = document.getElementById("run-banner");
  banner.innerHTML = f.connected ? "" :
    `<div class="banner" id="gone">The fleet does not answer; the page catches up when it returns.</div>`;
  if (r && (r.decided !== shown.decided || r.state !== shown.state)) {
    shown = {decided: r.decided, state: r.state};
    drawRun();
  }
}

function connect() {
  const feed = new EventSource("/events");
  feed.addEventListener("fleet", e => onFleet(JSON.parse(e.data)));
  feed.onerror = () => setLink("lost", "the page's server does not answer; retrying");
}

if (runId) { runSkeleton(); drawRun(); }
connect();

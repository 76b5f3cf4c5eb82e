// mpmweb's page: the runs table and one run's view, plain JS, no build step.
//
// Everything the daemon says (names, errors, warnings) is set with
// textContent, never parsed as markup.  A live job follows /api/events/JOB
// (Server-Sent Events): its record, its energy history, then progress,
// energy, snapshot notices and finished; samples are merged by their seq
// (a gap is filled from /api/energy) and the record is polled while the job
// runs, so a lost "finished" is noticed too.  A past run draws its energy
// series and a slider over its recorded snapshots.  For the browser test,
// the canvases carry what they drew: data-energy-points, data-particles-drawn,
// data-snapshot-step.
"use strict";

const $ = (id) => document.getElementById(id);
const num = (v) => (v === undefined || v === null ? NaN : Number(v));
const LIVE = { QUEUED: 1, RUNNING: 1 };

let config = { allowControl: false };
let view = null; // the open run view's state

async function api(path, opts) {
  const r = await fetch(path, opts);
  let body = null;
  try { body = await r.json(); } catch (e) { body = null; }
  if (!r.ok) {
    const e = body && body.error ? body.error : { code: "HTTP " + r.status, message: r.statusText };
    const err = new Error(e.code + ": " + e.message);
    err.status = r.status;
    throw err;
  }
  return body;
}

function fmtNum(v, digits) {
  v = num(v);
  if (!isFinite(v)) return "-";
  return Number(v.toPrecision(digits || 4)).toString();
}

function fmtDuration(s) {
  if (!isFinite(s) || s < 0) return "-";
  if (s < 60) return s.toFixed(1) + " s";
  if (s < 3600) return Math.floor(s / 60) + "m" + String(Math.floor(s % 60)).padStart(2, "0") + "s";
  return Math.floor(s / 3600) + "h" + String(Math.floor((s % 3600) / 60)).padStart(2, "0") + "m";
}

function fmtTime(unix) {
  unix = num(unix);
  if (!(unix > 0)) return "-";
  const d = new Date(unix * 1000);
  return d.toLocaleString();
}

// ---- runs table ---------------------------------------------------------------

const list = { before: 0, next: 0, timer: null };

async function loadRuns() {
  const q = new URLSearchParams();
  const st = $("f-status").value, name = $("f-name").value, limit = $("f-limit").value;
  if (st) q.set("status", st);
  if (name) q.set("name", name);
  if (limit) q.set("limit", limit);
  if (list.before) q.set("before", String(list.before));
  const tbody = document.querySelector("#runs tbody");
  try {
    const page = await api("/api/runs?" + q.toString());
    const runs = page.runs || [];
    list.next = num(page.nextBeforeRunId) || 0;
    tbody.replaceChildren();
    for (const r of runs) {
      const tr = document.createElement("tr");
      const cells = [
        r.runId, r.jobId, r.name || "", r.status || "", r.steps || "0", fmtNum(r.t),
        r.particles || "", r.method || "", fmtTime(r.submittedAt),
        r.balanceError !== undefined ? fmtNum(100 * num(r.balanceError), 3) + " %" : "-",
      ];
      cells.forEach((c, i) => {
        const td = document.createElement("td");
        if (i === 2) td.className = "name";
        if (i === 3) {
          const s = document.createElement("span");
          s.className = "status " + String(c).replace(/[^A-Z]/g, "");
          s.textContent = c;
          td.appendChild(s);
        } else {
          td.textContent = String(c);
        }
        tr.appendChild(td);
      });
      tr.dataset.run = String(r.runId);
      tr.addEventListener("click", () => { location.hash = "run=" + r.runId; });
      tbody.appendChild(tr);
    }
    $("runs-msg").textContent = runs.length ? "" : "no runs" + (name ? " on this page match the name" : "");
    $("f-older").disabled = !list.next;
    document.body.dataset.runsShown = String(runs.length);
  } catch (e) {
    $("runs-msg").textContent = "cannot list the runs: " + e.message;
  }
}

function setupRuns() {
  const reload = () => { list.before = 0; loadRuns(); };
  $("f-status").addEventListener("change", reload);
  $("f-limit").addEventListener("change", reload);
  $("f-name").addEventListener("input", reload);
  $("filters").addEventListener("submit", (e) => { e.preventDefault(); reload(); });
  $("f-newest").addEventListener("click", reload);
  $("f-older").addEventListener("click", () => { if (list.next) { list.before = list.next; loadRuns(); } });
  $("submit-go").addEventListener("click", async () => {
    $("submit-msg").textContent = "";
    try {
      const ok = await api("/api/submit", {
        method: "POST", headers: { "Content-Type": "application/json", "X-Mpmweb": "1" },
        body: $("submit-case").value,
      });
      location.hash = "run=" + ok.runId;
    } catch (e) {
      $("submit-msg").textContent = e.message;
    }
  });
}

// ---- energy plot -------------------------------------------------------------------

const SERIES = [["kinetic", "#1f77b4"], ["strain", "#ff7f0e"], ["total", "#222"]];

function addSample(v, s) {
  const seq = num(s.seq);
  if (!isFinite(seq) || v.seen.has(seq)) return false;
  v.seen.add(seq);
  v.samples.push({ seq, t: num(s.t), step: num(s.step), kinetic: num(s.kinetic),
    strain: num(s.strain), total: num(s.total), balance: num(s.balanceError) });
  if (seq > v.maxSeq) v.maxSeq = seq;
  v.sorted = false;
  return true;
}

function drawEnergy(v) {
  const cv = $("energy"), g = cv.getContext("2d");
  const W = cv.width, H = cv.height, L = 70, R = 12, T = 12, B = 34;
  if (!v.sorted) { v.samples.sort((a, b) => a.seq - b.seq); v.sorted = true; }
  const s = v.samples;
  g.clearRect(0, 0, W, H);
  g.font = "11px sans-serif";
  g.fillStyle = "#555";
  if (!s.length) {
    g.fillText("no energy samples yet", L, H / 2);
    cv.dataset.energyPoints = "0";
    return;
  }
  let t0 = s[0].t, t1 = s[s.length - 1].t, lo = Infinity, hi = -Infinity;
  for (const p of s) for (const [k] of SERIES) if (isFinite(p[k])) { lo = Math.min(lo, p[k]); hi = Math.max(hi, p[k]); }
  if (!(t1 > t0)) t1 = t0 + 1;
  if (!(hi > lo)) { hi = lo + 1; lo -= 1; }
  const pad = 0.05 * (hi - lo); lo -= pad; hi += pad;
  const X = (t) => L + ((t - t0) / (t1 - t0)) * (W - L - R);
  const Y = (e) => T + (1 - (e - lo) / (hi - lo)) * (H - T - B);
  g.strokeStyle = "#ddd";
  g.lineWidth = 1;
  for (let i = 0; i <= 4; i++) {
    const e = lo + (i / 4) * (hi - lo), y = Y(e);
    g.beginPath(); g.moveTo(L, y); g.lineTo(W - R, y); g.stroke();
    g.fillText(fmtNum(e, 3), 4, y + 4);
  }
  for (let i = 0; i <= 4; i++) {
    const t = t0 + (i / 4) * (t1 - t0);
    g.fillText(fmtNum(t, 3), X(t) - 10, H - 18);
  }
  g.fillText("t", W / 2, H - 4);
  const stride = Math.max(1, Math.floor(s.length / 4000)); // at most ~4000 vertices per line
  for (const [k, colour] of SERIES) {
    g.strokeStyle = colour;
    g.lineWidth = 1.6;
    g.setLineDash(k === "total" ? [6, 4] : []); // total dashed: kinetic shows beneath it
    g.beginPath();
    let first = true;
    for (let i = 0; i < s.length; i += stride) {
      const p = s[i];
      if (!isFinite(p[k])) continue;
      if (first) { g.moveTo(X(p.t), Y(p[k])); first = false; } else g.lineTo(X(p.t), Y(p[k]));
    }
    const p = s[s.length - 1];
    if (!first && isFinite(p[k])) g.lineTo(X(p.t), Y(p[k]));
    g.stroke();
  }
  g.setLineDash([]);
  const last = s[s.length - 1];
  $("r-balance").textContent = isFinite(last.balance) ? "balance error " + fmtNum(100 * last.balance, 3) + " %" : "";
  cv.dataset.energyPoints = String(s.length);
  cv.dataset.energyLastT = String(last.t);
}

async function fillGap(v, from) {
  if (v.filling) return;
  v.filling = true;
  try {
    for (let guard = 0; guard < 1000; guard++) {
      const page = await api("/api/energy/" + v.runId + "?from=" + from);
      if (v !== view) return;
      const ss = page.samples || [];
      ss.forEach((s) => addSample(v, s));
      if (!page.more || !ss.length) break;
      from = num(ss[ss.length - 1].seq) + 1;
    }
    drawEnergy(v);
  } catch (e) {
    /* the next sample or poll tries again */
  } finally {
    v.filling = false;
  }
}

// ---- particles ----------------------------------------------------------------------

// viridis, 6 stops
const STOPS = [[68, 1, 84], [65, 68, 135], [42, 120, 142], [34, 168, 132], [122, 209, 81], [253, 231, 37]];
function colour(u) {
  if (!isFinite(u)) return "rgb(160,160,160)";
  u = Math.min(1, Math.max(0, u)) * (STOPS.length - 1);
  const i = Math.min(STOPS.length - 2, Math.floor(u)), f = u - i, a = STOPS[i], b = STOPS[i + 1];
  return "rgb(" + Math.round(a[0] + f * (b[0] - a[0])) + "," + Math.round(a[1] + f * (b[1] - a[1])) +
    "," + Math.round(a[2] + f * (b[2] - a[2])) + ")";
}

function drawColorbar() {
  const cv = $("cbar"), g = cv.getContext("2d");
  for (let i = 0; i < cv.width; i++) { g.fillStyle = colour(i / (cv.width - 1)); g.fillRect(i, 0, 1, cv.height); }
}

// The grid's extent (the view box, so frames do not jump) and the particle
// spacing (spacing / ppc of the first body) from the run's case.
function gridBox(c) {
  const g = c && c.grid;
  if (!g || !g.origin || !g.spacing || !g.nodes) return null;
  const d = g.origin.length, o = g.origin.map(num), h = g.spacing.map(num), n = g.nodes.map(num);
  const ppc = c.bodies && c.bodies.length && c.bodies[0].ppc ? num(c.bodies[0].ppc) : 2;
  return { x0: o[0], x1: o[0] + h[0] * (n[0] - 1), y0: d > 1 ? o[1] : -h[0], y1: d > 1 ? o[1] + h[1] * (n[1] - 1) : h[0],
    dp: h[0] / Math.max(1, ppc), fixed: true };
}

function drawParticles(v) {
  const snap = v.snap, cv = $("particles"), g = cv.getContext("2d");
  g.clearRect(0, 0, cv.width, cv.height);
  if (!snap || !snap.x) return;
  const n = snap.n, d = snap.dim, x = snap.x;
  const field = $("field").value, f = snap.fields ? snap.fields[field] : null;
  // the view box grows to hold every frame drawn, so frames do not jump
  const bb = v.grid || v.bbox || { x0: Infinity, x1: -Infinity, y0: Infinity, y1: -Infinity };
  for (let i = 0; i < n && !bb.fixed; i++) {
    const px = x[i * d], py = d > 1 ? x[i * d + 1] : 0;
    if (!isFinite(px) || !isFinite(py)) continue;
    bb.x0 = Math.min(bb.x0, px); bb.x1 = Math.max(bb.x1, px);
    bb.y0 = Math.min(bb.y0, py); bb.y1 = Math.max(bb.y1, py);
  }
  v.bbox = bb;
  let w = bb.x1 - bb.x0, h = bb.y1 - bb.y0;
  if (!(w > 0)) w = h > 0 ? h : 1;
  if (!(h > 0)) h = w;
  const m = 8, scale = Math.min((cv.width - 2 * m) / w, (cv.height - 2 * m) / h);
  const cx = (bb.x0 + bb.x1) / 2, cy = (bb.y0 + bb.y1) / 2;
  const dp = bb.dp || Math.sqrt((w * h) / Math.max(1, n));
  const r = Math.max(1, Math.min(8, 0.5 * scale * dp * 0.95));
  if (bb.fixed) { // the grid's outline
    g.strokeStyle = "#ccc";
    g.strokeRect(cv.width / 2 + (bb.x0 - cx) * scale, cv.height / 2 - (bb.y1 - cy) * scale, w * scale, h * scale);
  }
  // the colour range: the 1st to 99th percentile, so a few contact particles
  // do not wash out the rest (the bar shows the range; beyond it, the ends)
  let lo = Infinity, hi = -Infinity;
  if (f) {
    const vals = f.filter((q) => q !== null && isFinite(q)).sort((a, b) => a - b);
    if (vals.length) {
      lo = vals[Math.floor(0.01 * (vals.length - 1))];
      hi = vals[Math.ceil(0.99 * (vals.length - 1))];
    }
  }
  if (!(hi > lo)) { hi = lo + 1; }
  let drawn = 0;
  for (let i = 0; i < n; i++) {
    const px = x[i * d], py = d > 1 ? x[i * d + 1] : 0;
    if (!isFinite(px) || !isFinite(py)) continue;
    g.fillStyle = f ? colour((num(f[i]) - lo) / (hi - lo)) : "#2f7de1";
    g.beginPath();
    g.arc(cv.width / 2 + (px - cx) * scale, cv.height / 2 - (py - cy) * scale, r, 0, 2 * Math.PI);
    g.fill();
    drawn++;
  }
  $("cb-min").textContent = f ? fmtNum(lo, 3) : "";
  $("cb-max").textContent = f ? fmtNum(hi, 3) : "";
  $("snap-info").textContent = "step " + snap.step + ", t " + fmtNum(snap.t, 5) + ", " + n + " particles" +
    (f ? "" : " (" + field + " not in this snapshot)");
  cv.dataset.particlesDrawn = String(drawn);
  cv.dataset.snapshotStep = String(snap.step);
  cv.dataset.field = field;
}

async function loadSnapshot(v, path) {
  if (v.snapBusy) { v.snapPending = path; return; }
  v.snapBusy = true;
  try {
    const s = await api(path);
    if (v !== view) return;
    if (!v.snap || num(s.step) >= num(v.snap.step) || !v.live) { v.snap = s; drawParticles(v); }
  } catch (e) {
    /* no snapshot yet */
  } finally {
    v.snapBusy = false;
    if (v.snapPending && v === view) { const p = v.snapPending; v.snapPending = null; loadSnapshot(v, p); }
  }
}

// ---- one run ------------------------------------------------------------------------------

function showRun(v, run) {
  v.run = run;
  const st = run.status || "";
  $("r-title").textContent = (run.name || "run") + " (run " + run.runId + ", job " + run.jobId + ")";
  $("r-status").textContent = st;
  $("r-status").className = "status " + st.replace(/[^A-Z]/g, "");
  $("r-info").textContent = [run.method, run.update, run.transfer].filter(Boolean).join(" / ") +
    ", " + (run.particles || "?") + " particles, " + (run.nodes || "?") + " nodes, submitted " + fmtTime(run.submittedAt) +
    (run.owner ? ", by " + run.owner : "");
  $("r-error").textContent = [run.error, run.warning].filter(Boolean).join("\n");
  $("r-cancel").hidden = !(config.allowControl && LIVE[st]);
  document.body.dataset.runStatus = st;
  if (!LIVE[st]) {
    const steps = num(run.steps);
    $("r-bar").style.width = st === "FINISHED" ? "100%" : $("r-bar").style.width;
    $("r-progress").textContent = "steps " + steps + ", t " + fmtNum(run.t, 6) + ", wall " + fmtDuration(num(run.wallS));
  }
}

function showProgress(p) {
  const step = num(p.step), total = num(p.stepsTotal), wall = num(p.wallS);
  const frac = total > 0 ? Math.min(1, step / total) : 0;
  $("r-bar").style.width = (100 * frac).toFixed(1) + "%";
  const eta = step > 0 && total > step ? (wall * (total - step)) / step : NaN;
  $("r-progress").textContent = "step " + step + (total > 0 ? " / " + total + " (" + (100 * frac).toFixed(1) + " %)" : "") +
    ", t " + fmtNum(p.t, 6) + ", dt " + fmtNum(p.dt, 3) + ", wall " + fmtDuration(wall) +
    (isFinite(eta) ? ", ETA " + fmtDuration(eta) : "");
}

function closeView() {
  if (!view) return;
  if (view.es) view.es.close();
  if (view.poll) clearInterval(view.poll);
  view = null;
}

function followLive(v) {
  const es = new EventSource("/api/events/" + v.jobId);
  v.es = es;
  es.addEventListener("run", (e) => { if (v === view) showRun(v, JSON.parse(e.data)); });
  es.addEventListener("history", (e) => {
    if (v !== view) return;
    JSON.parse(e.data).forEach((s) => addSample(v, s));
    drawEnergy(v);
  });
  es.addEventListener("energy", (e) => {
    if (v !== view) return;
    const m = JSON.parse(e.data), s = m.energy;
    if (!s) return;
    const seq = num(s.seq), before = v.maxSeq;
    if (addSample(v, s)) {
      if (seq > before + 1) fillGap(v, before + 1);
      drawEnergy(v);
    }
  });
  es.addEventListener("progress", (e) => {
    if (v !== view) return;
    const m = JSON.parse(e.data);
    if (m.progress) showProgress(m.progress);
  });
  es.addEventListener("snapshot", () => {
    if (v === view) loadSnapshot(v, "/api/live/" + v.jobId);
  });
  es.addEventListener("finished", () => {
    if (v !== view) return;
    es.close();
    setTimeout(() => { if (v === view) openRun(v.runId); }, 300);
  });
  // the record, now and then: the status, and an end the stream lost
  v.poll = setInterval(async () => {
    if (v !== view) return;
    try {
      const run = await api("/api/run/" + v.runId);
      if (v !== view) return;
      showRun(v, run);
      if (!LIVE[run.status]) { es.close(); openRun(v.runId); }
    } catch (e) { /* keep going */ }
  }, 3000);
}

function setupSlider(v, steps, want) {
  const box = $("slider-box"), sl = $("slider");
  box.hidden = steps.length < 1;
  if (!steps.length) return;
  sl.min = "0";
  sl.max = String(steps.length - 1);
  let at = steps.length - 1;
  if (want !== undefined) {
    // the recorded snapshot nearest the step asked for (#run=ID&step=N)
    let best = Infinity;
    steps.forEach((st, i) => { const dd = Math.abs(Number(st) - want); if (dd < best) { best = dd; at = i; } });
  }
  sl.value = String(at);
  const show = () => {
    const st = steps[Number(sl.value)];
    $("slider-label").textContent = "snapshot " + (Number(sl.value) + 1) + " of " + steps.length + " (step " + st + ")";
    loadSnapshot(v, "/api/snapshot/" + v.runId + "?step=" + st);
  };
  sl.oninput = show;
  show();
}

async function openRun(runId, step) {
  closeView();
  const v = { runId, samples: [], seen: new Set(), maxSeq: -1, sorted: true, live: false };
  view = v;
  document.body.dataset.view = "run";
  $("runs-view").hidden = true;
  $("run-view").hidden = false;
  $("slider-box").hidden = true;
  $("r-bar").style.width = "0";
  $("r-progress").textContent = "";
  ["energy", "particles"].forEach((id) => { const c = $(id); c.getContext("2d").clearRect(0, 0, c.width, c.height); });
  let run;
  try {
    run = await api("/api/run/" + runId + "?case=1");
  } catch (e) {
    $("r-title").textContent = "run " + runId;
    $("r-error").textContent = e.message;
    return;
  }
  if (v !== view) return;
  v.jobId = run.jobId;
  v.grid = gridBox(run.case);
  delete run.case;
  showRun(v, run);
  if (LIVE[run.status]) {
    v.live = true;
    followLive(v);
    loadSnapshot(v, "/api/snapshot/" + runId); // the latest recorded one, until the stream brings one
  } else {
    fillGap(v, 0);
    setupSlider(v, (run.snapshotSteps || []).map(String), step);
  }
}

// ---- routing --------------------------------------------------------------------------------

function route() {
  const m = /^#run=(\d+)(?:&step=(\d+))?$/.exec(location.hash);
  if (m) {
    openRun(m[1], m[2] !== undefined ? Number(m[2]) : undefined);
    return;
  }
  closeView();
  document.body.dataset.view = "runs";
  $("run-view").hidden = true;
  $("runs-view").hidden = false;
  loadRuns();
}

async function main() {
  try {
    config = await api("/api/config");
    $("conn").textContent = "mpmd " + config.version + " at " + config.endpoint + (config.allowControl ? " (control enabled)" : " (read-only)");
  } catch (e) {
    $("conn").textContent = "gateway: " + e.message;
  }
  $("submit-box").hidden = !config.allowControl;
  setupRuns();
  drawColorbar();
  $("field").addEventListener("change", () => { if (view) drawParticles(view); });
  $("r-cancel").addEventListener("click", async () => {
    if (!view) return;
    try {
      await api("/api/cancel/" + view.jobId, { method: "POST", headers: { "X-Mpmweb": "1" } });
    } catch (e) {
      $("r-error").textContent = e.message;
    }
  });
  window.addEventListener("hashchange", route);
  list.timer = setInterval(() => { if (!view && !list.before) loadRuns(); }, 5000);
  route();
}

main();

// The guided recording, the live coverage view and a session's jobs (rig/web/live.py).
// Plain JS, no build step, no inline script: the page's data comes in data-* attributes.
//
// The live view keeps, for the latency benchmark and the browser tests, window.rigLive:
//   draws    [{what, seq, sample_ms, drawn_ms}] — when each status (counters) or coverage
//            (swing map) event's newest sample (its host time on the Unix clock) reached the
//            screen (the animation frame after the DOM was updated), on this machine's clock;
//            at most 10,000 kept
//   events   {name: count} of the events received
//   coverage the last coverage event drawn
"use strict";

(function () {
  const live = { draws: [], events: {}, coverage: null, status: null, ended: null };
  window.rigLive = live;

  function csrfHeaders() {
    const h = { "Content-Type": "application/json" };
    const m = document.cookie.match(/(?:^|;\s*)csrftoken=([^;]+)/);
    if (m) h["x-csrftoken"] = decodeURIComponent(m[1]);
    const meta = document.querySelector('meta[name="csrf-token"]');
    if (meta) h["x-csrftoken"] = meta.content;
    return h;
  }

  async function post(url, body) {
    const r = await fetch(url, {
      method: "POST", headers: csrfHeaders(), credentials: "same-origin",
      body: JSON.stringify(body || {}),
    });
    let data = {};
    try { data = await r.json(); } catch (e) { data = { error: "HTTP " + r.status }; }
    if (!r.ok) throw new Error(data.error || data.detail || ("HTTP " + r.status));
    return data;
  }

  function showError(text) {
    const el = document.getElementById("error");
    if (!el) return;
    el.textContent = text;
    el.hidden = !text;
  }

  function now() { return performance.timeOrigin + performance.now(); }

  // -- the recording form ----------------------------------------------------------------
  const form = document.getElementById("record-form");
  if (form) {
    form.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      showError("");
      const f = new FormData(form);
      const body = {
        patient_id: f.get("patient_id") || null,
        rig: f.get("rig") || "",
        side: f.get("side") || null,
        duration_s: f.get("duration_s") || null,
        calibrate: f.get("calibrate") === "on",
      };
      const button = document.getElementById("start");
      button.disabled = true;
      try {
        const res = await post(form.dataset.action, body);
        window.location.assign(res.url);
      } catch (e) {
        showError(e.message);
        button.disabled = false;
      }
    });
  }

  // -- a session's jobs ------------------------------------------------------------------
  for (const b of document.querySelectorAll("button.start-job")) {
    b.addEventListener("click", async () => {
      showError("");
      b.disabled = true;
      const body = {};
      const preset = b.dataset.preset && document.getElementById(b.dataset.preset);
      if (preset && preset.value) body.preset = preset.value;
      try {
        const res = await post(b.dataset.action, body);
        window.location.assign(res.url);
      } catch (e) {
        showError(e.message);
        b.disabled = false;
      }
    });
  }

  // -- a job -----------------------------------------------------------------------------
  const job = document.getElementById("job");
  if (!job) return;
  const id = job.dataset.job;
  const kind = job.dataset.kind;
  const $ = (x) => document.getElementById(x);

  function text(elId, value) { const el = $(elId); if (el) el.textContent = value; }
  function fmt(x, nd) { return x === null || x === undefined ? "–" : Number(x).toFixed(nd || 0); }

  for (const [button, action] of [["continue", "continue"], ["stop", "stop"],
                                   ["interrupt", "interrupt"]]) {
    const el = $(button);
    if (!el) continue;
    el.addEventListener("click", async () => {
      showError("");
      try { await post(`/api/jobs/${id}/${action}`); } catch (e) { showError(e.message); }
    });
  }

  const COMPASS = ["→", "↗", "↑", "↖", "←", "↙", "↓", "↘"];

  function onStatus(s) {
    live.status = s;
    text("phase", s.phase);
    text("elapsed", fmt(s.elapsed_s, 1) + (s.duration_s ? " / " + s.duration_s + " s" : " s"));
    text("samples", String(s.samples));
    text("rate", fmt(s.rate_hz) + " /s");
    text("dropped", String(s.dropped));
    text("checkpoints", s.checkpoints === null ? "–" : String(s.checkpoints));
    const prompt = $("prompt");
    if (prompt) {
      prompt.hidden = !s.enter;
      text("prompt-text", s.enter ? "Continue: " + s.enter : "");
    }
    $("dropped") && $("dropped").classList.toggle("bad", s.dropped > 0);
    drawn("status", s);
  }

  function drawn(what, ev) {
    if (ev.sample_ms === null || ev.sample_ms === undefined) return;
    requestAnimationFrame(() => {
      live.draws.push({ what: what, seq: ev.seq, sample_ms: ev.sample_ms, drawn_ms: now() });
      if (live.draws.length > 10000) live.draws.shift();
    });
  }

  function sectorState(sec) {
    // [a0, a1, reach, boundary, samples, twist_min, twist_max, stable, explored]
    if (sec[8]) return "explored";
    if (sec[4] && !sec[7]) return "still growing";
    if (sec[4]) return "needs samples near the limit";
    return "not visited";
  }

  function drawMap(c) {
    const canvas = $("swing-map");
    if (!canvas) return;
    const g = canvas.getContext("2d");
    const W = canvas.width, H = canvas.height, cx = W / 2, cy = H / 2, R = Math.min(W, H) / 2 - 14;
    let maxReach = 90;
    for (const s of c.sectors) if (s[2] !== null) maxReach = Math.max(maxReach, s[2] + 10);
    for (const p of c.reached) maxReach = Math.max(maxReach, p[1] + 5);
    maxReach = Math.min(180, Math.ceil(maxReach / 30) * 30);
    const k = R / maxReach;
    const xy = (az, rho) => {
      const a = az * Math.PI / 180;
      return [cx + rho * k * Math.cos(a), cy - rho * k * Math.sin(a)];
    };
    g.clearRect(0, 0, W, H);
    g.fillStyle = "#fff";
    g.fillRect(0, 0, W, H);
    // each sector filled to its reach: green explored, amber growing, none grey
    for (const s of c.sectors) {
      const st = sectorState(s);
      const reach = s[2] === null ? 0 : s[2];
      g.beginPath();
      g.moveTo(cx, cy);
      g.arc(cx, cy, reach * k, -s[1] * Math.PI / 180, -s[0] * Math.PI / 180);
      g.closePath();
      g.fillStyle = st === "explored" ? "rgba(46,157,77,0.35)" :
        st === "not visited" ? "rgba(0,0,0,0)" : "rgba(230,160,20,0.30)";
      g.fill();
    }
    // rings every 30°, sector spokes
    g.strokeStyle = "#bbb";
    g.lineWidth = 1;
    g.fillStyle = "#666";
    g.font = "11px sans-serif";
    for (let r = 30; r <= maxReach; r += 30) {
      g.beginPath(); g.arc(cx, cy, r * k, 0, 2 * Math.PI); g.stroke();
      g.fillText(r + "°", cx + 3, cy - r * k + 12);
    }
    for (const s of c.sectors) {
      const [x, y] = xy(s[0], maxReach);
      g.beginPath(); g.moveTo(cx, cy); g.lineTo(x, y); g.stroke();
    }
    // the cells visited
    g.fillStyle = "#1f4e9c";
    for (const p of c.reached) {
      const [x, y] = xy(p[0], p[1]);
      g.fillRect(x - 1.5, y - 1.5, 3, 3);
    }
    // each sector's reach as an arc
    g.lineWidth = 3;
    for (const s of c.sectors) {
      if (s[2] === null) continue;
      g.strokeStyle = s[8] ? "#2e9d4d" : "#d08a00";
      g.beginPath();
      g.arc(cx, cy, s[2] * k, -s[1] * Math.PI / 180, -s[0] * Math.PI / 180);
      g.stroke();
    }
    g.lineWidth = 1;
    g.fillStyle = "#000";
    g.beginPath(); g.arc(cx, cy, 3, 0, 2 * Math.PI); g.fill();
  }

  function onCoverage(c) {
    live.coverage = c;
    drawMap(c);
    drawn("coverage", c);
    const n = c.sectors.length;
    text("explored", n ? `${c.explored} / ${n}` : "–");
    text("twist", c.twist[0] === null ? "–" : `${fmt(c.twist[0])}° .. ${fmt(c.twist[1])}°`);
    const banner = $("sufficient");
    if (banner) {
      banner.textContent = !n ? "" : c.sufficient ? "COVERAGE SUFFICIENT — you may stop" :
        `coverage: ${c.explored}/${n} directions explored — move to the limits in the others`;
      banner.className = "banner " + (c.sufficient ? "ok" : "todo");
    }
    const angles = $("angles");
    if (angles && c.angles) {
      const body = angles.tBodies[0];
      body.replaceChildren();
      for (const [joint, moves] of Object.entries(c.angles)) {
        for (const [movement, deg] of Object.entries(moves)) {
          const tr = body.insertRow();
          tr.insertCell().textContent = joint;
          tr.insertCell().textContent = movement.replace(/_/g, " ");
          tr.insertCell().textContent = deg === null ? "–" : fmt(deg) + "°";
        }
      }
      $("angles-box").hidden = !body.rows.length;
    }
    const left = $("left");
    if (left) {
      left.replaceChildren();
      for (const s of c.sectors) {
        if (s[8]) continue;
        const li = document.createElement("li");
        const mid = (s[0] + s[1]) / 2;
        const arrow = COMPASS[Math.floor(((mid + 22.5) % 360) / 45)];
        const st = sectorState(s);
        let why = st;
        if (st === "needs samples near the limit") why += ` (${s[3]} of ${c.need})`;
        li.textContent = `${arrow} ${fmt(s[0])}–${fmt(s[1])}°: ${why}` +
          (s[2] === null ? "" : `, reach ${fmt(s[2])}°`);
        left.appendChild(li);
      }
      if (n && !left.children.length) {
        const li = document.createElement("li");
        li.textContent = "nothing: every direction explored";
        left.appendChild(li);
      }
    }
  }

  function onMessage(m) {
    const li = document.createElement("li");
    li.textContent = m.text;
    $("log").appendChild(li);
  }

  function onSession(s) {
    const sid = s.session_id;
    $("work-link").href = `/sessions/${sid}/work`;
    $("session-link").href = `/sessions/${sid}`;
    job.dataset.session = sid;
  }

  function onEnd(e, source) {
    live.ended = e;
    text("state", e.status);
    job.dataset.state = e.status;
    const end = $("end");
    end.textContent = e.message || e.status;
    end.hidden = false;
    end.className = "end " + (e.status === "completed" ? "ok" : "bad");
    for (const b of ["stop", "interrupt", "continue"]) if ($(b)) $(b).disabled = true;
    if ($("prompt")) $("prompt").hidden = true;
    const sid = job.dataset.session || (e.result && e.result.session_id);
    if (sid) { onSession({ session_id: sid }); $("next").hidden = false; }
    source.close();
  }

  const source = new EventSource(`/api/jobs/${id}/events`);
  const handlers = { status: onStatus, coverage: onCoverage, message: onMessage,
                     session: onSession };
  for (const [name, fn] of Object.entries(handlers)) {
    source.addEventListener(name, (ev) => {
      live.events[name] = (live.events[name] || 0) + 1;
      const data = JSON.parse(ev.data);
      data.seq = Number(ev.lastEventId);
      fn(data);
    });
  }
  source.addEventListener("end", (ev) => {
    live.events.end = (live.events.end || 0) + 1;
    onEnd(JSON.parse(ev.data), source);
  });
  if (kind !== "record") {
    for (const el of ["stop", "interrupt"]) if ($(el)) $(el).hidden = true;
  }
})();

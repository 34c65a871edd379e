// imutool bridge display: heel gauge and numerals, roll amplitude, period, peak-hold, status, trend.
// Data: the WebSocket /ws of `imutool live --http` (reconnects by itself); no external asset.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const R = 170, MAXDEG = 45, TREND_S = 600, STALE_S = 2.0;
  const state = { trend: [], lastMsg: 0, stopped: "", connected: false, messages: 0, last: null };
  window.imutoolDisplay = state;  // for tests and benchmarks: message count and the last snapshot shown

  // ---- palettes -----------------------------------------------------------------------------------------
  function setPalette(name) {
    document.body.className = name;
    for (const b of document.querySelectorAll("#palettes button")) b.classList.toggle("active", b.dataset.palette === name);
    try { localStorage.setItem("imutool-palette", name); } catch (e) { /* private mode */ }
  }
  for (const b of document.querySelectorAll("#palettes button")) b.addEventListener("click", () => setPalette(b.dataset.palette));
  const wanted = new URLSearchParams(location.search).get("palette");
  let saved = null; try { saved = localStorage.getItem("imutool-palette"); } catch (e) { /* private mode */ }
  setPalette(["day", "dusk", "night"].includes(wanted) ? wanted : (saved || "day"));

  // ---- gauge ------------------------------------------------------------------------------------------
  const pt = (deg, r) => { const a = deg * Math.PI / 180; return [r * Math.sin(a), -r * Math.cos(a)]; };
  const arc = (d0, d1, r) => { const [x0, y0] = pt(d0, r), [x1, y1] = pt(d1, r); return `M${x0.toFixed(1)},${y0.toFixed(1)} A${r},${r} 0 0 1 ${x1.toFixed(1)},${y1.toFixed(1)}`; };
  $("arc-port").setAttribute("d", arc(-MAXDEG, 0, R));
  $("arc-stbd").setAttribute("d", arc(0, MAXDEG, R));
  const ns = "http://www.w3.org/2000/svg";
  for (let d = -MAXDEG; d <= MAXDEG; d += 5) {
    const [x0, y0] = pt(d, R - 8), [x1, y1] = pt(d, R - (d % 10 === 0 ? 30 : 20));
    const l = document.createElementNS(ns, "line");
    l.setAttribute("x1", x0); l.setAttribute("y1", y0); l.setAttribute("x2", x1); l.setAttribute("y2", y1);
    $("ticks").appendChild(l);
    if (d % 10 === 0 && d !== 0) {
      const [tx, ty] = pt(d, R + 24), t = document.createElementNS(ns, "text");
      t.setAttribute("x", tx); t.setAttribute("y", ty + 6); t.textContent = Math.abs(d);
      $("ticks").appendChild(t);
    }
  }
  const clamp = (v) => Math.max(-MAXDEG, Math.min(MAXDEG, v));

  // ---- formatting ---------------------------------------------------------------------------------------
  const num = (v, d = 1) => (v === null || v === undefined || !isFinite(v)) ? "--.-" : Number(v).toFixed(d);
  const utcText = (epoch) => new Date(epoch * 1000).toISOString().slice(11, 19) + " UTC";
  const isoText = (iso) => iso ? iso.replace("T", " ").replace(/\.\d+/, "").replace(/(Z|\+00:00)$/, "") + " UTC" : "never";

  function setStatus(letter, cause) {
    const el = $("status");
    el.className = letter === "A" ? "status-a" : "status-v";
    el.dataset.status = letter;
    $("status-letter").textContent = letter;
    $("status-cause").textContent = letter === "A" ? "estimate valid" : cause;
    document.body.classList.toggle("stale", letter !== "A" && !state.connected);
  }

  function show(s) {
    state.last = s; state.messages += 1; state.lastMsg = performance.now();
    const roll = s.roll_deg, valid = roll !== null && isFinite(roll);
    const side = !valid || Math.abs(roll) < 0.05 ? "" : (roll > 0 ? "S" : "P");
    $("heel-value").textContent = valid ? Math.abs(roll).toFixed(1) : "--.-";
    $("heel-side").textContent = side || "\u00a0";
    $("heel-read").className = side === "S" ? "stbd" : side === "P" ? "port" : "";
    $("heel").dataset.roll = valid ? String(roll) : "";
    $("heel").dataset.t = String(s.t);
    $("ship").setAttribute("transform", `rotate(${valid ? clamp(roll).toFixed(2) : 0})`);
    $("amp-port").textContent = num(s.roll_amp_port_deg); $("amp-stbd").textContent = num(s.roll_amp_stbd_deg);
    $("period").textContent = num(s.roll_period_s);
    $("peak-port").textContent = num(s.peak_port_deg); $("peak-stbd").textContent = num(s.peak_stbd_deg);
    $("peak-reset").textContent = isoText(s.peak_reset_utc);
    const pp = s.peak_port_deg, ps = s.peak_stbd_deg;
    $("peak-p").setAttribute("d", pp > 0 ? arc(-clamp(pp) - 0.9, -clamp(pp) + 0.9, R) : "M0,0");
    $("peak-s").setAttribute("d", ps > 0 ? arc(clamp(ps) - 0.9, clamp(ps) + 0.9, R) : "M0,0");
    $("pitch").textContent = num(s.pitch_deg);
    const hv = s.heave_m !== null && s.heave_m !== undefined && isFinite(s.heave_m);
    $("row-heave").hidden = !hv; if (hv) $("heave").textContent = num(s.heave_m, 2);
    $("clock").textContent = utcText(s.utc);
    setStatus(s.status, s.cause || "not valid");
    addTrend(s);
  }

  // ---- trend --------------------------------------------------------------------------------------------
  function addTrend(s) {
    if (s.roll_deg === null || !isFinite(s.roll_deg)) return;
    const tr = state.trend;
    if (tr.length && s.t < tr[tr.length - 1][0]) tr.length = 0;  // a new run: start again
    if (!tr.length || s.t - tr[tr.length - 1][0] >= 1.0) tr.push([s.t, s.roll_deg]);
    while (tr.length && tr[0][0] < s.t - TREND_S) tr.shift();
    drawTrend();
  }
  function drawTrend() {
    const tr = state.trend; if (!tr.length) return;
    const tEnd = tr[tr.length - 1][0];
    const big = Math.max(5, ...tr.map((p) => Math.abs(p[1])));
    const range = Math.ceil(big / 5) * 5;
    $("trend-range").textContent = range;
    $("trend-line").setAttribute("points", tr.map(([t, r]) =>
      `${(600 * (t - tEnd + TREND_S) / TREND_S).toFixed(1)},${(60 - 60 * r / range).toFixed(1)}`).join(" "));
  }

  // ---- reset with confirmation --------------------------------------------------------------------------
  $("reset").addEventListener("click", () => { $("confirm").hidden = false; });
  $("confirm-no").addEventListener("click", () => { $("confirm").hidden = true; });
  $("confirm-yes").addEventListener("click", () => {
    $("confirm").hidden = true;
    fetch("/api/reset", { method: "POST" }).catch(() => setStatus("V", "reset not sent: no connection to imutool"));
  });

  // ---- the feed: WebSocket, reconnecting ----------------------------------------------------------------
  function connect() {
    const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
    ws.onopen = () => { state.connected = true; state.stopped = ""; state.lastMsg = performance.now(); };
    ws.onmessage = (ev) => {
      const m = JSON.parse(ev.data);
      if (m.type === "history") { state.trend = []; for (const s of m.items) addTrend(s); state.lastMsg = performance.now(); }
      else if (m.type === "snapshot") show(m);
      else if (m.type === "stopped") { state.stopped = m.reason; setStatus("V", `imutool stopped: ${m.reason}`); }
    };
    ws.onclose = () => {
      state.connected = false;
      setStatus("V", state.stopped ? `imutool stopped: ${state.stopped}; reconnecting` : "no connection to imutool; reconnecting");
      setTimeout(connect, 1000);
    };
  }
  setInterval(() => {  // no data for STALE_S: the reading is not valid
    const quiet = (performance.now() - state.lastMsg) / 1000;
    if (state.connected && !state.stopped && state.lastMsg && quiet > STALE_S) setStatus("V", `no data from imutool for ${quiet.toFixed(0)} s`);
  }, 500);
  connect();
})();

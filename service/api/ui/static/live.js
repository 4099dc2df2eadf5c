// skyfix console, /ui/live: watch a stream session (WS /v1/sessions/{name}/watch).
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const WINDOW_S = 600; // plots and statistics: the last 10 minutes
  const MAGNIFY = 50;
  const hist = { t: [], ra: [], raLo: [], raHi: [], dec: [], decLo: [], decHi: [], roll: [], rollLo: [], rollHi: [], rate: [] };
  const frames = []; // {t, solved, latency} of every frame in the window
  let ws = null, cameras = {}, lastCam = null, count = 0, dirty = false;

  Sky.bindKey($("apikey"));
  $("magnify").textContent = MAGNIFY;

  // ---- charts (uPlot) ---------------------------------------------------------------------------
  function chart(id, title, unit, color, band) {
    const el = $(id);
    const series = [{}, { label: title, stroke: color, width: 1.5, spanGaps: false, value: (u, v) => (v == null ? "-" : v.toFixed(4) + unit) }];
    const axis = { stroke: "#94a3b8", grid: { stroke: "#1e293b", width: 1 }, ticks: { stroke: "#334155", width: 1 } };
    const opts = { title, width: 560, height: 170, series, legend: { show: true }, axes: [axis, Object.assign({ size: 70 }, axis)],
      scales: { x: { time: true }, y: unit ? {} : { range: [0, 1.05] } } };
    if (band) {
      series.push({ label: "-1σ", stroke: color + "55", width: 1, value: (u, v) => (v == null ? "-" : v.toFixed(4)) },
        { label: "+1σ", stroke: color + "55", width: 1, value: (u, v) => (v == null ? "-" : v.toFixed(4)) });
      opts.bands = [{ series: [3, 2], fill: color + "33" }];
    }
    const plot = new uPlot(opts, series.map(() => []), el);
    return { el, plot };
  }
  const charts = {
    ra: chart("chart-ra", "RA", "°", "#60a5fa", true),
    dec: chart("chart-dec", "Dec", "°", "#34d399", true),
    roll: chart("chart-roll", "roll", "°", "#f472b6", true),
    rate: chart("chart-rate", "solved, last 10 s", "", "#facc15", false),
  };

  SkyMap.init("skymap", 420);

  // ---- connection --------------------------------------------------------------------------------
  async function loadCameras() {
    try { cameras = (await Sky.getJSON("/v1/info")).cameras || {}; } catch (_) { /* 401 without a key */ }
  }

  function connect() {
    if (ws) { ws.onclose = null; ws.close(); ws = null; setStatus("not connected", false); $("connect").textContent = "Watch"; return; }
    const name = $("session").value.trim();
    loadCameras();
    ws = new WebSocket(Sky.wsUrl(`/v1/sessions/${encodeURIComponent(name)}/watch`));
    setStatus("connecting…", false);
    $("connect").textContent = "Stop";
    let opened = false;
    ws.onopen = () => { opened = true; setStatus(`watching ${name}`, true); };
    ws.onclose = () => {
      ws = null;
      $("connect").textContent = "Watch";
      // a refused handshake (wrong key, bad name) reaches the page as a bare close before open
      setStatus(opened ? "disconnected" : "refused or unreachable: check the API key and the session name", false);
    };
    ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
  }
  $("connect").addEventListener("click", connect);

  function setStatus(text, on) {
    const s = $("status");
    s.textContent = text;
    s.classList.toggle("on", on);
  }

  // ---- one published frame ---------------------------------------------------------------------
  function onMessage(msg) {
    const result = msg.result;
    $("dropped").textContent = msg.dropped;
    if (result.status === "config") return; // a StreamAck
    const now = Date.now() / 1000;
    count += 1;
    $("frames").textContent = count;
    const solved = result.status === "solved";
    const latency = result.timings_ms && result.timings_ms.total;
    frames.push({ t: now, solved, latency: latency ?? null });
    trim(now);
    const recent = frames.filter((f) => f.t >= now - 10);
    hist.t.push(now);
    hist.rate.push(recent.filter((f) => f.solved).length / recent.length);
    const sig = result.attitude_sigma_arcsec, cross = sig ? Math.max(sig[0], sig[1]) / 3600 : 0;
    const add = (key, v, s) => {
      hist[key].push(solved ? v : null);
      hist[key + "Lo"].push(solved ? v - s : null);
      hist[key + "Hi"].push(solved ? v + s : null);
    };
    add("ra", result.ra_deg, solved ? cross / Math.max(0.01, Math.cos(result.dec_deg * Math.PI / 180)) : 0);
    add("dec", result.dec_deg, cross);
    add("roll", result.roll_deg, sig ? sig[2] / 3600 : 0);
    if (result.code !== undefined) { $("frame-info").textContent = `frame ${result.id}: ${result.code} ${result.field || ""} ${result.detail}`; dirty = true; return; }
    drawLatest(msg, result);
    dirty = true;
  }

  function trim(now) {
    while (frames.length && frames[0].t < now - WINDOW_S) frames.shift();
    while (hist.t.length && hist.t[0] < now - WINDOW_S) for (const k of Object.keys(hist)) hist[k].shift();
  }

  // centroids and camera of the frame: from its text message, or (image frames) from the result
  function frameOf(msg, result) {
    let req = null;
    if (msg.frame) { try { req = JSON.parse(msg.frame); } catch (_) { /* not JSON: no centroids */ } }
    let spec = null, rows = [];
    if (req && req.centroids) { spec = req.camera; rows = req.centroids; }
    else if (req && req.cameras && req.cameras.length) { spec = req.cameras[0].camera; rows = req.cameras[0].centroids; }
    if (typeof spec === "string") spec = cameras[spec] || null;
    let cam = spec && spec.width ? Sky.camera(spec) : null;
    if (!req) { rows = result.centroids || []; if (result.wcs) cam = Sky.cameraFromWcs(result.wcs); }
    cam = cam || lastCam;
    if (!cam && rows.length) {
      const w = Math.max(...rows.map((r) => r[0])) + 20, h = Math.max(...rows.map((r) => r[1])) + 20;
      cam = { w, h, f: NaN, cx: w / 2, cy: h / 2 };
    }
    return { rows, cam, rig: !!(req && req.cameras) };
  }

  function drawLatest(msg, result) {
    const { rows, cam, rig } = frameOf(msg, result);
    if (!cam) return;
    lastCam = cam;
    const canvas = $("frame"), ctx = canvas.getContext("2d");
    const scale = Math.min(640 / cam.w, 480 / cam.h);
    canvas.width = Math.round(cam.w * scale);
    canvas.height = Math.round(cam.h * scale);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.save();
    ctx.scale(scale, scale);
    ctx.translate(0.5, 0.5);
    Sky.drawFrame(ctx, cam, rows, result, { magnify: MAGNIFY, scale, camera: 0 });
    ctx.restore();
    $("frame-info").textContent = `frame ${result.id} (#${msg.seq}) · ${cam.w}x${cam.h} px${rig ? " · rig: camera 0" : ""}` +
      ` · ${(result.stars || []).length} of ${rows.length} identified`;
    const kv = [["status", result.status + (result.reason ? ` (${result.reason})` : "")],
      ["RA / Dec / roll", `${Sky.fmt(result.ra_deg, 4)}° / ${Sky.fmt(result.dec_deg, 4)}° / ${Sky.fmt(result.roll_deg, 3)}°`],
      ["1σ x, y, roll", result.attitude_sigma_arcsec ? result.attitude_sigma_arcsec.map((v) => v.toFixed(1)).join(", ") + " arcsec" : "-"],
      ["RMS residual", Sky.fmt(result.rms_arcsec, 2) + " arcsec"], ["method", result.method]];
    $("attitude").replaceChildren(...kv.map(([k, v]) => {
      const tr = document.createElement("tr");
      for (const c of [k, v]) { const td = document.createElement("td"); td.textContent = c; tr.append(td); }
      return tr;
    }));
    if (result.quaternion && !rig && Number.isFinite(cam.f)) {
      SkyMap.show(Sky.footprint(cam, result.quaternion), result.ra_deg, result.dec_deg);
      const sky = $("skymap");
      sky.dataset.center = `${result.ra_deg.toFixed(3)},${result.dec_deg.toFixed(3)}`;
      $("sky-info").textContent = `boresight RA ${result.ra_deg.toFixed(3)}°, Dec ${result.dec_deg.toFixed(3)}°`;
    }
  }

  // ---- plots and statistics, at most 4 times a second ----------------------------------------
  function quantile(sorted, q) {
    if (!sorted.length) return null;
    return sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
  }

  setInterval(() => {
    if (!dirty) return;
    dirty = false;
    const t = hist.t;
    charts.ra.plot.setData([t, hist.ra, hist.raLo, hist.raHi]);
    charts.dec.plot.setData([t, hist.dec, hist.decLo, hist.decHi]);
    charts.roll.plot.setData([t, hist.roll, hist.rollLo, hist.rollHi]);
    charts.rate.plot.setData([t, hist.rate]);
    for (const c of Object.values(charts)) c.el.dataset.points = String(t.length);
    const now = Date.now() / 1000;
    const lat = frames.map((f) => f.latency).filter((v) => v !== null).sort((a, b) => a - b);
    $("p50").textContent = lat.length ? quantile(lat, 0.5).toFixed(1) + " ms" : "-";
    $("p99").textContent = lat.length ? quantile(lat, 0.99).toFixed(1) + " ms" : "-";
    const span = frames.length ? Math.max(1, Math.min(10, now - frames[0].t)) : 10;
    $("fps").textContent = (frames.filter((f) => f.t >= now - 10).length / span).toFixed(1);
    $("rate").textContent = frames.length ? (100 * frames.filter((f) => f.solved).length / frames.length).toFixed(1) + "%" : "-";
  }, 250);

  // ?session=NAME&watch=1 starts watching at once (the key, if the server needs one, is typed first)
  const params = new URLSearchParams(window.location.search);
  if (params.get("session")) $("session").value = params.get("session");
  if (params.get("watch") === "1") connect();
})();

// skyfix console, /ui/solve: upload an image (or paste centroids), show the stars and the attitude.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const MAGNIFY = 50;
  let cameras = {}; // configured cameras by name (GET /v1/info)
  let urls = [];

  Sky.bindKey($("apikey"));
  $("magnify").textContent = MAGNIFY;

  async function loadCameras() {
    try {
      cameras = (await Sky.getJSON("/v1/info")).cameras || {};
    } catch (e) {
      return; // 401 until the key is typed; the camera list stays as it is
    }
    const sel = $("camera"), keep = sel.value;
    sel.replaceChildren(new Option("(none)", ""));
    for (const name of Object.keys(cameras)) sel.add(new Option(`${name} (${cameras[name].width}x${cameras[name].height})`, name));
    sel.value = keep in cameras ? keep : "";
  }
  $("apikey").addEventListener("change", loadCameras);
  loadCameras();

  function showError(e) {
    const box = $("error");
    box.textContent = Sky.errorText(e);
    box.hidden = false;
  }

  function clear() {
    $("error").hidden = true;
    $("attitude").replaceChildren();
    $("stars").replaceChildren();
    $("result-json").textContent = "";
    for (const id of ["dl-json", "dl-wcs"]) $(id).hidden = true;
    urls.forEach((u) => URL.revokeObjectURL(u));
    urls = [];
  }

  // ---- image upload with progress (XHR: fetch has no upload progress) ---------------------------
  function upload(file) {
    clear();
    const form = new FormData();
    form.append("image", file, file.name);
    const fov = $("fov").value.trim(), cam = $("camera").value;
    if (fov) form.append("fov_deg", fov);
    if (cam) form.append("camera", cam);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", "/v1/solve/image");
    for (const [k, v] of Object.entries(Sky.headers())) xhr.setRequestHeader(k, v);
    const bar = $("progress"), text = $("progress-text");
    bar.value = 0;
    text.textContent = "uploading…";
    xhr.upload.onprogress = (ev) => {
      if (ev.lengthComputable) {
        bar.value = ev.loaded / ev.total;
        text.textContent = `uploading ${Math.round(100 * ev.loaded / ev.total)}% of ${(ev.total / 1e6).toFixed(2)} MB`;
      }
    };
    xhr.upload.onload = () => { bar.value = 1; text.textContent = "uploaded; solving…"; };
    xhr.onerror = () => { text.textContent = ""; showError(new Error("network error: the service did not answer")); };
    xhr.onload = async () => {
      let body = null;
      try { body = JSON.parse(xhr.responseText); } catch (_) { /* not JSON */ }
      if (xhr.status >= 400 || !body) {
        text.textContent = "";
        showError(Sky.apiError(xhr.status, body));
        return;
      }
      text.textContent = `done (${body.status})`;
      const bitmap = await createImageBitmap(file).catch(() => null); // TIFF and FITS: no preview
      show(body, body.centroids || [], imageCamera(body, bitmap), bitmap);
    };
    xhr.send(form);
  }

  function imageCamera(result, bitmap) {
    if (result.wcs) return Sky.cameraFromWcs(result.wcs);
    if (bitmap) return { w: bitmap.width, h: bitmap.height, f: NaN, cx: bitmap.width / 2, cy: bitmap.height / 2 };
    return boundsCamera(result.centroids || []);
  }

  function boundsCamera(rows) {
    const w = Math.max(16, ...rows.map((r) => r[0] + 10)), h = Math.max(16, ...rows.map((r) => r[1] + 10));
    return { w, h, f: NaN, cx: w / 2, cy: h / 2 };
  }

  // ---- a pasted centroid list -------------------------------------------------------------------
  async function solveJson() {
    clear();
    const text = $("centroids").value;
    let req = null;
    try { req = JSON.parse(text); } catch (_) { /* the service says what is wrong */ }
    const r = await fetch("/v1/solve", { method: "POST", headers: Sky.headers({ "Content-Type": "application/json" }), body: text });
    const body = await r.json().catch(() => null);
    if (!r.ok) { showError(Sky.apiError(r.status, body)); return; }
    let spec = req && req.camera;
    if (typeof spec === "string") spec = cameras[spec];
    const rows = (req && req.centroids) || [];
    show(body, rows, spec ? Sky.camera(spec) : boundsCamera(rows), null);
  }
  $("solve-json").addEventListener("click", solveJson);

  // ---- result ---------------------------------------------------------------------------------
  function show(result, rows, cam, bitmap) {
    const canvas = $("image"), ctx = canvas.getContext("2d");
    const scale = Math.min(1, 900 / cam.w);
    canvas.width = Math.round(cam.w * scale);
    canvas.height = Math.round(cam.h * scale);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (bitmap) {
      ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
      stretch(ctx, canvas.width, canvas.height);
    }
    ctx.save();
    ctx.scale(scale, scale);
    ctx.translate(0.5, 0.5); // pixel centres
    Sky.drawFrame(ctx, cam, rows, result, { magnify: MAGNIFY, scale });
    ctx.restore();
    canvas.dataset.identified = String((result.stars || []).length);
    canvas.dataset.detected = String(rows.length);

    const sig = result.attitude_sigma_arcsec;
    const kv = [
      ["status", result.status + (result.reason ? ` (${result.reason})` : "")],
      ["RA", Sky.fmt(result.ra_deg, 4) + "°"], ["Dec", Sky.fmt(result.dec_deg, 4) + "°"], ["roll", Sky.fmt(result.roll_deg, 3) + "°"],
      ["1σ x, y, roll", sig ? sig.map((v) => v.toFixed(1)).join(", ") + " arcsec" : "-"],
      ["RMS residual", Sky.fmt(result.rms_arcsec, 2) + " arcsec"],
      ["false-match probability", result.false_match_probability == null ? "-" : result.false_match_probability.toExponential(2)],
      ["stars", `${(result.stars || []).length} identified of ${result.n_detected ?? rows.length}`],
      ["method", result.method], ["time", Sky.fmt(result.timings_ms && result.timings_ms.total, 1) + " ms"],
    ];
    if (result.message) kv.push(["message", result.message]);
    $("attitude").replaceChildren(...kv.map(([k, v]) => row([k, v], "td")));
    const head = row(["HIP", "V", "RA °", "Dec °", "x px", "y px", "residual ″"], "th");
    $("stars").replaceChildren(head, ...(result.stars || []).map((s) => {
      const c = rows[s.centroid] || [NaN, NaN];
      return row([s.hip, s.mag.toFixed(2), s.ra_deg.toFixed(4), s.dec_deg.toFixed(4), c[0].toFixed(1), c[1].toFixed(1), s.residual_arcsec.toFixed(2)], "td");
    }));
    const json = JSON.stringify(result, null, 2);
    $("result-json").textContent = json;
    link("dl-json", new Blob([json], { type: "application/json" }));
    if (result.wcs) link("dl-wcs", new Blob([fitsHeader(result.wcs)], { type: "application/fits" }));
  }

  // Star fields are dark: the sky (99.5th percentile and below) to black, the brightest stars to white; display only.
  function stretch(ctx, w, h) {
    const img = ctx.getImageData(0, 0, w, h), px = img.data, hist = new Uint32Array(256);
    for (let i = 0; i < px.length; i += 4) hist[(px[i] + px[i + 1] + px[i + 2]) / 3 | 0] += 1;
    const level = (q) => { let n = 0; for (let v = 0; v < 256; v++) { n += hist[v]; if (n >= q * w * h) return v; } return 255; };
    const lo = level(0.995), hi = Math.max(lo + 40, level(0.99995));
    const lut = new Uint8ClampedArray(256);
    for (let v = 0; v < 256; v++) lut[v] = 255 * Math.sqrt(Math.max(0, Math.min(1, (v - lo) / (hi - lo))));
    for (let i = 0; i < px.length; i += 4) { px[i] = lut[px[i]]; px[i + 1] = lut[px[i + 1]]; px[i + 2] = lut[px[i + 2]]; }
    ctx.putImageData(img, 0, 0);
  }

  function row(cells, tag) {
    const tr = document.createElement("tr");
    for (const c of cells) { const td = document.createElement(tag); td.textContent = String(c); tr.append(td); }
    return tr;
  }

  function link(id, blob) {
    const a = $(id), url = URL.createObjectURL(blob);
    urls.push(url);
    a.href = url;
    a.hidden = false;
  }

  // A header-only FITS file (like astrometry.net's wcs.fits): 80-character cards, padded to 2880 bytes.
  function fitsHeader(wcs) {
    const card = (key, value, comment) => {
      let v = typeof value === "string" ? `'${value.padEnd(8)}'`.padEnd(20) : typeof value === "boolean" ? (value ? "T" : "F").padStart(20)
        : (Number.isInteger(value) ? String(value) : value.toExponential(12).toUpperCase()).padStart(20);
      return `${key.padEnd(8)}= ${v}${comment ? " / " + comment : ""}`.slice(0, 80).padEnd(80);
    };
    const cards = [card("SIMPLE", true, "file conforms to FITS"), card("BITPIX", 8), card("NAXIS", 0, "header only"),
      card("EXTEND", true), card("WCSAXES", 2)];
    for (const [k, v] of Object.entries(wcs)) {
      if (k === "NAXIS1") cards.push(card("IMAGEW", v, "image width, px"));
      else if (k === "NAXIS2") cards.push(card("IMAGEH", v, "image height, px"));
      else cards.push(card(k, v));
    }
    cards.push("HISTORY solved by skyfix".padEnd(80));
    cards.push("END".padEnd(80));
    let text = cards.join("");
    text = text.padEnd(Math.ceil(text.length / 2880) * 2880);
    return text;
  }

  // ---- drop / choose --------------------------------------------------------------------------
  const drop = $("drop");
  drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    if (e.dataTransfer.files.length) upload(e.dataTransfer.files[0]);
  });
  $("file").addEventListener("change", (e) => { if (e.target.files.length) upload(e.target.files[0]); e.target.value = ""; });
})();

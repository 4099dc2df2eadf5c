// skyfix console: shared helpers (API key in page memory, API calls, camera geometry, frame drawing).
// No framework; loaded by live.html and solve.html before their own script.
"use strict";

const Sky = (() => {
  let apiKey = ""; // typed by the user; kept in this variable only (never stored, never in the page)

  function bindKey(input) {
    input.value = "";
    input.addEventListener("input", () => { apiKey = input.value.trim(); });
  }

  function headers(extra) {
    const h = Object.assign({}, extra || {});
    if (apiKey) h["X-API-Key"] = apiKey;
    return h;
  }

  function wsUrl(path, params) {
    const u = new URL(path, window.location.href);
    u.protocol = u.protocol === "https:" ? "wss:" : "ws:";
    for (const [k, v] of Object.entries(params || {})) if (v !== null && v !== undefined && v !== "") u.searchParams.set(k, v);
    if (apiKey) u.searchParams.set("api_key", apiKey); // browsers cannot set headers on a WebSocket
    return u.toString();
  }

  function apiError(status, body) {
    const detail = body && typeof body.detail === "string" ? body.detail : "HTTP " + status;
    const e = new Error(detail);
    e.status = status;
    e.field = body && body.field ? body.field : null;
    return e;
  }

  // "422 fov_deg: must be ..." - the service's message as it is, naming the field
  function errorText(e) {
    return (e.status ? e.status + " " : "") + (e.field ? e.field + ": " : "") + e.message;
  }

  async function getJSON(path) {
    const r = await fetch(path, { headers: headers() });
    const body = await r.json().catch(() => null);
    if (!r.ok) throw apiError(r.status, body);
    return body;
  }

  // ---- camera geometry (pinhole; pixel origin the centre of the top-left pixel) ----------------
  const D2R = Math.PI / 180;

  // {w, h, f, cx, cy} from a CameraSpec object
  function camera(spec) {
    const w = spec.width, h = spec.height;
    let f = spec.f_px;
    if (spec.fov_deg) f = (w / 2) / Math.tan(spec.fov_deg * D2R / 2);
    else if (spec.focal_mm && spec.pixel_um) f = spec.focal_mm * 1000 / spec.pixel_um;
    return { w, h, f, cx: spec.cx ?? (w - 1) / 2, cy: spec.cy ?? (h - 1) / 2 };
  }

  // camera of an image result from its FITS WCS (CRPIX is 1-based)
  function cameraFromWcs(wcs) {
    const det = Math.abs(wcs.CD1_1 * wcs.CD2_2 - wcs.CD1_2 * wcs.CD2_1);
    return { w: wcs.NAXIS1, h: wcs.NAXIS2, f: 1 / (Math.sqrt(det) * D2R), cx: wcs.CRPIX1 - 1, cy: wcs.CRPIX2 - 1 };
  }

  // ICRS -> camera rotation matrix of a quaternion [w, x, y, z]
  function matrix(q) {
    const n = Math.hypot(...q), [w, x, y, z] = q.map((v) => v / n);
    return [
      [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ];
  }

  function unit(raDeg, decDeg) {
    const a = raDeg * D2R, d = decDeg * D2R;
    return [Math.cos(d) * Math.cos(a), Math.cos(d) * Math.sin(a), Math.sin(d)];
  }

  // pixel position of the sky direction (ra, dec) seen by cam at attitude R, or null behind the camera
  function project(cam, R, raDeg, decDeg) {
    const v = unit(raDeg, decDeg);
    const c = R.map((row) => row[0] * v[0] + row[1] * v[1] + row[2] * v[2]);
    if (c[2] <= 1e-9) return null;
    return [cam.cx + cam.f * c[0] / c[2], cam.cy + cam.f * c[1] / c[2]];
  }

  // sky direction [ra, dec] (deg) of pixel (x, y)
  function unproject(cam, R, x, y) {
    const d = [(x - cam.cx) / cam.f, (y - cam.cy) / cam.f, 1];
    const v = [0, 1, 2].map((j) => R[0][j] * d[0] + R[1][j] * d[1] + R[2][j] * d[2]);
    const n = Math.hypot(...v);
    const ra = Math.atan2(v[1], v[0]) / D2R;
    return [(ra + 360) % 360, Math.asin(v[2] / n) / D2R];
  }

  // the image outline on the sky: [[ra, dec], ...] closed, 8 points a side
  function footprint(cam, q) {
    const R = matrix(q), pts = [];
    const edge = (x0, y0, x1, y1) => { for (let i = 0; i < 8; i++) pts.push(unproject(cam, R, x0 + (x1 - x0) * i / 8, y0 + (y1 - y0) * i / 8)); };
    const W = cam.w - 0.5, H = cam.h - 0.5;
    edge(-0.5, -0.5, W, -0.5); edge(W, -0.5, W, H); edge(W, H, -0.5, H); edge(-0.5, H, -0.5, -0.5);
    pts.push(pts[0]);
    return pts;
  }

  // ---- frame drawing ---------------------------------------------------------------------------
  // Draw centroids (rows [x, y, flux?]) of one camera to scale on ctx (already scaled: 1 unit = 1 px of
  // the camera): identified stars ringed and labelled "HIP n  V m", others crossed, residual vectors
  // (catalogue position minus centroid) magnified `magnify` times.
  function drawFrame(ctx, cam, rows, result, opts) {
    const o = Object.assign({ magnify: 100, scale: 1, camera: 0 }, opts || {});
    const px = 1 / o.scale; // one screen pixel in camera pixels
    const stars = new Map();
    for (const s of (result && result.stars) || []) if ((s.camera || 0) === o.camera) stars.set(s.centroid, s);
    const R = result && result.quaternion ? matrix(result.quaternion) : null;
    ctx.lineWidth = 1.5 * px;
    ctx.font = `${12 * px}px sans-serif`;
    rows.forEach((row, i) => {
      const [x, y] = row, s = stars.get(i);
      if (s) {
        ctx.strokeStyle = "#4ade80";
        ctx.beginPath(); ctx.arc(x, y, 9 * px, 0, 2 * Math.PI); ctx.stroke();
        ctx.fillStyle = "#bbf7d0";
        ctx.fillText(`HIP ${s.hip}  V ${s.mag.toFixed(1)}`, x + 11 * px, y - 5 * px);
        const p = R ? project(cam, R, s.ra_deg, s.dec_deg) : null;
        if (p) {
          ctx.strokeStyle = "#f472b6";
          ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + (p[0] - x) * o.magnify, y + (p[1] - y) * o.magnify); ctx.stroke();
        }
      } else {
        ctx.strokeStyle = "#fb923c";
        const r = 5 * px;
        ctx.beginPath(); ctx.moveTo(x - r, y - r); ctx.lineTo(x + r, y + r); ctx.moveTo(x - r, y + r); ctx.lineTo(x + r, y - r); ctx.stroke();
      }
    });
  }

  function fmt(v, digits) { return v === null || v === undefined || Number.isNaN(v) ? "-" : Number(v).toFixed(digits); }

  return { bindKey, headers, wsUrl, apiError, errorText, getJSON, camera, cameraFromWcs, matrix, project, unproject, footprint, drawFrame, fmt };
})();

// Line plots on a 2d canvas: several series over a shared x axis, optional shaded contact
// bands, a legend and a cursor at the current time. Specs come from the report's JSON.

const PAD = { left: 52, right: 12, top: 26, bottom: 30 };

function niceTicks(lo, hi, count) {
  const span = hi - lo || 1;
  const raw = span / count;
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => span / s <= count) || 10 * mag;
  const ticks = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * span; v += step) ticks.push(v);
  return ticks;
}

function fmt(v) {
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(1);
  return String(Math.round(v * 1000) / 1000);
}

export function drawPlot(canvas, spec, cursorX) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const log = !!spec.log_y;
  const ty = (v) => (log ? Math.log10(Math.max(v, 1e-12)) : v);
  let xlo = Infinity, xhi = -Infinity, ylo = Infinity, yhi = -Infinity;
  for (const s of spec.series) {
    s.x = s.x || spec.x;
    for (let i = 0; i < s.y.length; i++) {
      if (s.y[i] === null) continue;
      xlo = Math.min(xlo, s.x[i]); xhi = Math.max(xhi, s.x[i]);
      ylo = Math.min(ylo, ty(s.y[i])); yhi = Math.max(yhi, ty(s.y[i]));
    }
  }
  if (!isFinite(xlo)) return;
  if (xhi === xlo) { xlo -= 0.5; xhi += 0.5; }
  const ymargin = (yhi - ylo || 1) * 0.08;
  ylo -= ymargin; yhi += ymargin;
  const px = (x) => PAD.left + ((x - xlo) / (xhi - xlo)) * (w - PAD.left - PAD.right);
  const py = (y) => h - PAD.bottom - ((y - ylo) / (yhi - ylo)) * (h - PAD.top - PAD.bottom);

  ctx.font = "11px sans-serif";
  ctx.fillStyle = "#222";
  ctx.fillText(spec.title, PAD.left, 14);
  // Shaded bands (e.g. foot contacts): one row per band series along the bottom.
  (spec.bands || []).forEach((band, k) => {
    ctx.fillStyle = band.color;
    const y0 = py(ylo) - (k + 1) * 6;
    for (let i = 0; i < band.on.length; i++) {
      if (!band.on[i]) continue;
      const x0 = px(spec.x[i]);
      const x1 = i + 1 < spec.x.length ? px(spec.x[i + 1]) : x0 + 2;
      ctx.fillRect(x0, y0, Math.max(1, x1 - x0), 5);
    }
  });
  ctx.strokeStyle = "#ccc";
  ctx.lineWidth = 1;
  ctx.fillStyle = "#555";
  for (const v of niceTicks(ylo, yhi, 4)) {
    ctx.beginPath(); ctx.moveTo(PAD.left, py(v)); ctx.lineTo(w - PAD.right, py(v)); ctx.stroke();
    ctx.fillText(log ? "1e" + fmt(v) : fmt(v), 4, py(v) + 4);
  }
  for (const v of niceTicks(xlo, xhi, 6)) ctx.fillText(fmt(v), px(v) - 6, h - PAD.bottom + 14);
  const xlabel = spec.xlabel || "";
  ctx.fillText(xlabel, w - PAD.right - ctx.measureText(xlabel).width, h - 4);
  ctx.fillText(spec.ylabel || "", PAD.left + 4, PAD.top + 6);
  // Series.
  let legendX = PAD.left + ctx.measureText(spec.title).width + 16;
  for (const s of spec.series) {
    ctx.strokeStyle = s.color;
    ctx.lineWidth = 1.6;
    ctx.setLineDash(s.dash ? [5, 3] : []);
    ctx.beginPath();
    let pen = false;
    for (let i = 0; i < s.y.length; i++) {
      if (s.y[i] === null) { pen = false; continue; }
      const X = px(s.x[i]), Y = py(ty(s.y[i]));
      if (pen) ctx.lineTo(X, Y); else ctx.moveTo(X, Y);
      pen = true;
      if (s.markers) ctx.fillRect(X - 2, Y - 2, 4, 4);
    }
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = s.color;
    ctx.fillRect(legendX, 8, 14, 3);
    ctx.fillStyle = "#222";
    ctx.fillText(s.name, legendX + 18, 13);
    legendX += ctx.measureText(s.name).width + 32;
  }
  if (cursorX !== null && cursorX !== undefined && spec.cursor) {
    ctx.strokeStyle = "#d33";
    ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(px(cursorX), PAD.top); ctx.lineTo(px(cursorX), h - PAD.bottom);
    ctx.stroke();
  }
}

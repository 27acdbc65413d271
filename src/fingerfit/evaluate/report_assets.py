"""The fixed parts of the study report page: its style sheet and the script of its
interactive 3D view (plain JavaScript on a canvas, no external files)."""

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.8em 0;font-size:.9em}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:left;vertical-align:top}th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
img{max-width:100%;border:1px solid #eee}figure{margin:.8em 0}.note{color:#555;font-size:.9em}
.warn{color:#8a4b00;font-weight:600}
#view{border:1px solid #ccc;background:#fcfcfc;cursor:grab}code{background:#f4f4f4;padding:0 .2em}
"""

VIEWER_JS = """
const data = JSON.parse(document.getElementById('model-data').textContent);
const cv = document.getElementById('view'), ctx = cv.getContext('2d');
const sel = document.getElementById('subject');
for (const s of Object.keys(data)) { const o = document.createElement('option'); o.textContent = s; sel.appendChild(o); }
let yaw = -0.5, pitch = 0.35, zoom = 1, drag = null, off = [0, 0];
function rot(q) {  // view rotation of a vector (mm): screen right, depth, screen up
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const x = cy * q[0] - sy * q[1], y0 = sy * q[0] + cy * q[1];
  return [x, cp * y0 - sp * q[2], sp * y0 + cp * q[2]];
}
function proj(p) { const r = rot(p); return [cv.width / 2 + off[0] + zoom * r[0], cv.height / 2 + off[1] - zoom * r[2]]; }
function points() { return data[sel.value].fingers.flatMap(f => [...f.centres, f.tip, ...(f.pad ? [f.pad] : []), ...f.landmarks]); }
function fit() {  // frame the hand: every centre, tip and landmark fills ~80 % of the canvas
  const r = points().map(rot);
  const lo = [0, 2].map(k => Math.min(...r.map(p => p[k]))), hi = [0, 2].map(k => Math.max(...r.map(p => p[k])));
  zoom = 0.8 * Math.min(cv.width / Math.max(hi[0] - lo[0], 1), cv.height / Math.max(hi[1] - lo[1], 1));
  off = [-zoom * (lo[0] + hi[0]) / 2, zoom * (lo[1] + hi[1]) / 2];
}
function line(a, b, color, w) { const p = proj(a), q = proj(b); ctx.strokeStyle = color; ctx.lineWidth = w;
  ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke(); }
function dot(a, color, r) { const p = proj(a); ctx.fillStyle = color; ctx.beginPath();
  ctx.arc(p[0], p[1], r, 0, 6.3); ctx.fill(); }
function text(s, x, y, color) { ctx.fillStyle = color; ctx.fillText(s, x, y); }
function triad() {  // the frame's axes, bottom left, rotating with the view
  const o = [55, cv.height - 55], cols = ['#c0392b', '#27ae60', '#2c3e8f'];
  ctx.font = '13px sans-serif'; ctx.textAlign = 'center'; ctx.textBaseline = 'middle';
  for (let k = 0; k < 3; k++) {
    const e = [0, 0, 0]; e[k] = 1; const r = rot(e);
    const p = [o[0] + 36 * r[0], o[1] - 36 * r[2]];
    ctx.strokeStyle = cols[k]; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(o[0], o[1]);
    ctx.lineTo(p[0], p[1]); ctx.stroke();
    text('xyz'[k], o[0] + 48 * r[0], o[1] - 48 * r[2], cols[k]);
  }
}
function scalebar() {  // 10 mm at the current zoom, bottom right
  const L = 10 * zoom, x1 = cv.width - 30, x0 = x1 - L, y = cv.height - 30;
  ctx.strokeStyle = '#000'; ctx.lineWidth = 2; ctx.beginPath();
  ctx.moveTo(x0, y - 5); ctx.lineTo(x0, y); ctx.lineTo(x1, y); ctx.lineTo(x1, y - 5); ctx.stroke();
  ctx.font = '13px sans-serif'; ctx.textAlign = 'center'; ctx.textBaseline = 'bottom';
  text('10 mm', (x0 + x1) / 2, y - 6, '#000');
}
function draw() {
  ctx.clearRect(0, 0, cv.width, cv.height);
  const d = data[sel.value];
  for (const f of d.fingers) {
    const pts = [...f.centres, f.tip];
    for (let i = 0; i < 3; i++) line(pts[i], pts[i + 1], '#888', 5);
    for (let i = 0; i < 3; i++) {
      const c = f.centres[i];
      for (const [ax, col] of [[f.axes[i], '#1f77b4'], [f.orthogonal[i], '#d62728']])
        line(c.map((v, k) => v - 12 * ax[k]), c.map((v, k) => v + 12 * ax[k]), col, 2);
      dot(c, '#000', 3.5);
    }
    for (const [c, ax] of f.second_axes)
      line(c.map((v, k) => v - 12 * ax[k]), c.map((v, k) => v + 12 * ax[k]), '#9467bd', 2);
    for (const l of f.landmarks) dot(l, '#2ca02c', 2.5);
    if (f.pad) { line(f.tip, f.pad, '#e377c2', 1); dot(f.pad, '#e377c2', 3.5); }
    dot(f.tip, '#ff7f0e', 4);
    const t = proj(f.tip); ctx.font = '13px sans-serif'; ctx.textAlign = 'left';
    ctx.textBaseline = 'middle'; text(f.name, t[0] + 8, t[1], '#333');
  }
  triad(); scalebar();
  ctx.font = '12px sans-serif'; ctx.textAlign = 'left'; ctx.textBaseline = 'top';
  text(d.frame, 10, 10, '#555');
}
cv.onmousedown = e => drag = [e.clientX, e.clientY, yaw, pitch];
window.onmouseup = () => drag = null;
window.onmousemove = e => { if (!drag) return; yaw = drag[2] + (e.clientX - drag[0]) / 150;
  pitch = drag[3] + (e.clientY - drag[1]) / 150; draw(); };
cv.onwheel = e => { e.preventDefault(); zoom *= e.deltaY < 0 ? 1.1 : 0.9; draw(); };
cv.ondblclick = () => { fit(); draw(); };
sel.onchange = () => { fit(); draw(); }; fit(); draw();
"""

// Attitude indicator: artificial horizon (roll, pitch), heading tape and depth.
// docs/ARCHITECTURE.md is the map of the whole program.

export function drawAttitude(canvas, t) {
  const ctx = canvas.getContext('2d');
  const w = canvas.width;
  const h = canvas.height;
  const cx = w / 2;
  const cy = h / 2 + 10;
  ctx.clearRect(0, 0, w, h);
  const roll = ((t && t.roll_deg) || 0) * (Math.PI / 180);
  const pitch = (t && t.pitch_deg) || 0;
  const pxPerDeg = 2.2;

  // Horizon.
  ctx.save();
  ctx.beginPath();
  ctx.arc(cx, cy, 80, 0, 2 * Math.PI);
  ctx.clip();
  ctx.translate(cx, cy);
  ctx.rotate(-roll);
  ctx.translate(0, pitch * pxPerDeg);
  ctx.fillStyle = '#2f6ea8';
  ctx.fillRect(-200, -400, 400, 400);
  ctx.fillStyle = '#5a3f26';
  ctx.fillRect(-200, 0, 400, 400);
  ctx.strokeStyle = '#fff';
  ctx.lineWidth = 1;
  ctx.font = '10px sans-serif';
  ctx.fillStyle = '#fff';
  for (let p = -30; p <= 30; p += 10) {
    const y = -p * pxPerDeg;
    ctx.beginPath();
    ctx.moveTo(p === 0 ? -80 : -20, y);
    ctx.lineTo(p === 0 ? 80 : 20, y);
    ctx.stroke();
    if (p !== 0) ctx.fillText(String(p), 24, y + 3);
  }
  ctx.restore();

  // Aircraft symbol.
  ctx.strokeStyle = '#ffcc00';
  ctx.lineWidth = 3;
  ctx.beginPath();
  ctx.moveTo(cx - 40, cy);
  ctx.lineTo(cx - 12, cy);
  ctx.lineTo(cx, cy + 8);
  ctx.lineTo(cx + 12, cy);
  ctx.lineTo(cx + 40, cy);
  ctx.stroke();

  // Heading tape.
  const hdg = t && Number.isFinite(t.heading_deg) ? t.heading_deg : null;
  ctx.fillStyle = '#0a141c';
  ctx.fillRect(0, 0, w, 24);
  ctx.fillStyle = '#e6eef5';
  ctx.strokeStyle = '#e6eef5';
  ctx.lineWidth = 1;
  ctx.font = '11px sans-serif';
  ctx.textAlign = 'center';
  if (hdg !== null) {
    const pxPerHdg = 3;
    for (let d = Math.floor((hdg - 60) / 10) * 10; d <= hdg + 60; d += 10) {
      const x = cx + (d - hdg) * pxPerHdg;
      ctx.beginPath();
      ctx.moveTo(x, 0);
      ctx.lineTo(x, d % 30 === 0 ? 8 : 4);
      ctx.stroke();
      if (d % 30 === 0) {
        const n = ((d % 360) + 360) % 360;
        const label = { 0: 'N', 90: 'E', 180: 'S', 270: 'W' }[n] ?? String(n);
        ctx.fillText(label, x, 19);
      }
    }
  }
  ctx.fillStyle = '#ffcc00';
  ctx.beginPath();
  ctx.moveTo(cx - 5, 24);
  ctx.lineTo(cx + 5, 24);
  ctx.lineTo(cx, 30);
  ctx.fill();

  // Readouts.
  ctx.textAlign = 'left';
  ctx.font = 'bold 14px ui-monospace, monospace';
  ctx.fillStyle = '#e6eef5';
  ctx.fillText(`HDG ${hdg === null ? '—' : hdg.toFixed(0).padStart(3, '0')}°`, 8, h - 8);
  ctx.textAlign = 'right';
  const depth = t && Number.isFinite(t.depth_m) ? `${t.depth_m.toFixed(2)} m` : '—';
  ctx.fillText(`DEPTH ${depth}`, w - 8, h - 8);
  const ap = t && t.autopilot;
  ctx.font = '11px sans-serif';
  ctx.fillStyle = '#9fd3ff';
  if (ap && ap.heading_target_deg != null) ctx.fillText(`hold ${ap.heading_target_deg.toFixed(0)}°`, w - 8, 44);
  if (ap && ap.depth_target_m != null) ctx.fillText(`hold ${ap.depth_target_m.toFixed(1)} m`, w - 8, 58);
}

// The head-up display drawn by the page over whatever camera is connected:
// heading tape (one heading: the estimate, labelled), depth ladder with the
// held depth and the vertical speed, and the horizon (pitch and roll).
// Every element is drawn grey with its age once its data is older than
// STALE_MS, so a frozen value never looks live. The words around it (armed,
// mode, battery, who drives, failsafe) are DOM elements (view.js).
// docs/ARCHITECTURE.md is the map of the whole program.

/** Data older than this is shown as stale. */
export const STALE_MS = 1000;

const LIVE = '#f4f8fb';
const STALE = '#8a96a0';
const TARGET = '#33d6ff';
const OUTLINE = 'rgba(0, 0, 0, 0.65)';
const TAPE_SPAN_DEG = 90;
const LADDER_SPAN_M = 4;

const isNum = (v) => typeof v === 'number' && Number.isFinite(v);

/** What the HUD shows, from telemetry and the ages the view computed. */
export function hudData(t, ageOf) {
  if (!t) return null;
  const e = t.estimate;
  const ap = t.autopilot || {};
  const estHeading = e && e.heading_valid && isNum(e.heading_deg);
  const estDepth = e && e.depth_valid && isNum(e.depth_m);
  return {
    heading: estHeading ? e.heading_deg : t.heading_deg,
    headingLabel: estHeading ? 'HDG est.' : 'HDG',
    headingAge: estHeading ? ageOf('estimate') : ageOf('attitude'),
    headingTarget: ap.heading_target_deg,
    depth: estDepth ? e.depth_m : t.depth_m,
    depthAge: estDepth ? ageOf('estimate') : ageOf('depth'),
    depthTarget: ap.depth_target_m,
    climb: estDepth ? e.climb_rate_mps : null,
    roll: t.roll_deg,
    pitch: t.pitch_deg,
    attitudeAge: ageOf('attitude'),
  };
}

/** Draws the HUD on `canvas` (sized to its box here) for `d` (hudData). */
export function drawHud(canvas, d) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  if (!d || w < 50 || h < 50) return;
  const scale = Math.max(0.75, Math.min(1.4, Math.min(w, h) / 480));
  ctx.lineJoin = 'round';
  horizon(ctx, w, h, scale, d);
  tape(ctx, w, scale, d);
  ladder(ctx, w, h, scale, d);
}

function colour(age) {
  return age <= STALE_MS ? LIVE : STALE;
}

function ageText(age) {
  if (age <= STALE_MS) return '';
  return Number.isFinite(age) ? ` ${Math.round(age / 1000)} s old` : ' no data';
}

/** Text with a dark outline, readable over any picture. */
function text(ctx, s, x, y, fill, align = 'center', size = 13) {
  ctx.font = `600 ${size}px ui-monospace, monospace`;
  ctx.textAlign = align;
  ctx.textBaseline = 'middle';
  ctx.lineWidth = 3;
  ctx.strokeStyle = OUTLINE;
  ctx.strokeText(s, x, y);
  ctx.fillStyle = fill;
  ctx.fillText(s, x, y);
}

function line(ctx, x0, y0, x1, y1, stroke, width = 2) {
  ctx.beginPath();
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
  ctx.lineWidth = width + 2;
  ctx.strokeStyle = OUTLINE;
  ctx.stroke();
  ctx.lineWidth = width;
  ctx.strokeStyle = stroke;
  ctx.stroke();
}

function tape(ctx, w, s, d) {
  const c = colour(d.headingAge);
  const cx = w / 2;
  // Between the armed/mode banner and the battery widget in the corners.
  const width = Math.max(160, Math.min(w * 0.5, 520 * s, w - 480));
  const top = 8 * s;
  const base = top + 26 * s;
  const ppd = width / TAPE_SPAN_DEG;
  if (isNum(d.heading)) {
    const first = Math.ceil((d.heading - TAPE_SPAN_DEG / 2) / 5) * 5;
    for (let deg = first; deg <= d.heading + TAPE_SPAN_DEG / 2; deg += 5) {
      const x = cx + (deg - d.heading) * ppd;
      const len = deg % 10 === 0 ? 8 * s : 4 * s;
      line(ctx, x, base, x, base - len, c, 1.5);
      if (deg % 30 === 0) {
        const n = ((deg % 360) + 360) % 360;
        const label = { 0: 'N', 90: 'E', 180: 'S', 270: 'W' }[n] ?? String(n).padStart(3, '0');
        text(ctx, label, x, top + 6 * s, c, 'center', 12 * s);
      }
    }
    if (isNum(d.headingTarget)) {
      let off = ((d.headingTarget - d.heading + 540) % 360) - 180;
      off = Math.max(-TAPE_SPAN_DEG / 2, Math.min(TAPE_SPAN_DEG / 2, off));
      const x = cx + off * ppd;
      ctx.beginPath();
      ctx.moveTo(x, base + 1);
      ctx.lineTo(x - 6 * s, base + 10 * s);
      ctx.lineTo(x + 6 * s, base + 10 * s);
      ctx.closePath();
      ctx.fillStyle = TARGET;
      ctx.fill();
    }
  }
  line(ctx, cx - width / 2, base, cx + width / 2, base, c, 1.5);
  line(ctx, cx, base - 12 * s, cx, base + 4 * s, '#ffd23f', 2.5);
  const value = isNum(d.heading) ? `${String(Math.round(((d.heading % 360) + 360) % 360) % 360).padStart(3, '0')}°` : '---';
  text(ctx, `${d.headingLabel} ${value}${ageText(d.headingAge)}`, cx, base + 20 * s, c, 'center', 15 * s);
}

function ladder(ctx, w, h, s, d) {
  const c = colour(d.depthAge);
  const x = w - 70 * s;
  const top = h * 0.22;
  const bottom = h * 0.72;
  const mid = (top + bottom) / 2;
  const ppm = (bottom - top) / LADDER_SPAN_M;
  line(ctx, x, top, x, bottom, c, 1.5);
  if (isNum(d.depth)) {
    const first = Math.ceil((d.depth - LADDER_SPAN_M / 2) * 2) / 2;
    for (let m = first; m <= d.depth + LADDER_SPAN_M / 2 + 1e-9; m += 0.5) {
      const y = mid + (m - d.depth) * ppm;
      const whole = Math.abs(m - Math.round(m)) < 1e-6;
      line(ctx, x, y, x + (whole ? 10 : 5) * s, y, c, 1.5);
      if (whole && m >= 0) text(ctx, `${Math.round(m)}`, x + 22 * s, y, c, 'center', 12 * s);
    }
    if (isNum(d.depthTarget)) {
      const off = Math.max(-LADDER_SPAN_M / 2, Math.min(LADDER_SPAN_M / 2, d.depthTarget - d.depth));
      const y = mid + off * ppm;
      ctx.beginPath();
      ctx.moveTo(x - 1, y);
      ctx.lineTo(x - 11 * s, y - 6 * s);
      ctx.lineTo(x - 11 * s, y + 6 * s);
      ctx.closePath();
      ctx.fillStyle = TARGET;
      ctx.fill();
      text(ctx, `hold ${d.depthTarget.toFixed(1)}`, x - 14 * s, y + (off > 0 ? 14 : -14) * s, TARGET, 'right', 12 * s);
    }
  }
  line(ctx, x - 14 * s, mid, x + 4 * s, mid, '#ffd23f', 2.5);
  const value = isNum(d.depth) ? `${d.depth.toFixed(2)} m` : '--- m';
  text(ctx, 'DEPTH', x, top - 26 * s, c, 'center', 12 * s);
  text(ctx, value, x - 18 * s, mid - 14 * s, c, 'right', 15 * s);
  if (isNum(d.climb) && d.depthAge <= STALE_MS) {
    const up = d.climb >= 0;
    const v = Math.abs(d.climb) < 0.005 ? '0.00' : Math.abs(d.climb).toFixed(2);
    text(ctx, `${up ? '↑' : '↓'} ${v} m/s`, x - 18 * s, mid + 14 * s, c, 'right', 13 * s);
  }
  if (d.depthAge > STALE_MS) text(ctx, ageText(d.depthAge).trim(), x, bottom + 14 * s, c, 'center', 12 * s);
}

function horizon(ctx, w, h, s, d) {
  const c = colour(d.attitudeAge);
  const cx = w / 2;
  const cy = h / 2;
  const ppd = (h * 0.5) / 40; // 40° of pitch fill half the height
  // The fixed reticle: where the vehicle points.
  line(ctx, cx - 44 * s, cy, cx - 14 * s, cy, '#ffd23f', 2.5);
  line(ctx, cx + 14 * s, cy, cx + 44 * s, cy, '#ffd23f', 2.5);
  line(ctx, cx - 14 * s, cy, cx, cy + 8 * s, '#ffd23f', 2.5);
  line(ctx, cx, cy + 8 * s, cx + 14 * s, cy, '#ffd23f', 2.5);
  if (!isNum(d.roll) || !isNum(d.pitch)) return;
  ctx.save();
  ctx.translate(cx, cy);
  ctx.rotate((-d.roll * Math.PI) / 180);
  ctx.translate(0, d.pitch * ppd);
  const half = Math.min(w * 0.22, 220 * s);
  line(ctx, -half, 0, -60 * s, 0, c, 2);
  line(ctx, 60 * s, 0, half, 0, c, 2);
  for (const p of [-20, -10, 10, 20]) {
    const y = -p * ppd;
    line(ctx, -30 * s, y, 30 * s, y, c, 1);
    text(ctx, `${p > 0 ? '+' : ''}${p}`, 44 * s, y, c, 'center', 11 * s);
  }
  ctx.restore();
  text(ctx, `pitch ${d.pitch >= 0 ? '+' : ''}${d.pitch.toFixed(0)}°  roll ${d.roll >= 0 ? '+' : ''}${d.roll.toFixed(0)}°${ageText(d.attitudeAge)}`,
    cx, cy + 40 * s, c, 'center', 12 * s);
}

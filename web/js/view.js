// The operator page's view: renders what the session knows into the DOM —
// the status bar, the HUD and attitude indicator, the video, the messages
// list, the control-request prompt, the rights/login banner, the control
// modes offered by the server, and the readouts and sliders that follow
// telemetry — and writes the logger entries that telemetry and server
// messages imply. Sends nothing: the controls do (controls.js).
// docs/ARCHITECTURE.md is the map of the whole program.
import { KEY_LABELS } from '/js/input.js';
import { drawAttitude } from '/js/attitude.js';

const $ = (id) => document.getElementById(id);
const fmt = (v, d) => (Number.isFinite(v) ? v.toFixed(d) : '—');
const MAX_MESSAGES = 100;

export class View {
  /** `session`: read for the welcome, telemetry and modes (session.js);
   * `logger`, `recorder`: the developer interface's (recorder.js). */
  constructor({ session, logger, recorder }) {
    this.session = session;
    this.logger = logger;
    this.recorder = recorder;
    this.requestTimer = null;
    this.rotation = 0;
  }

  // ---- connection and session --------------------------------------------

  connected() { setPill('conn', 'connected', 'ok'); }

  disconnected() { setPill('conn', 'disconnected — retrying', 'bad'); }

  /** `onPickMode(mode)`: called when the operator picks a control mode. */
  welcome(m, onPickMode) {
    this.showModes(m.modes || [], onPickMode);
    this.showRights();
    this.applyRotation(m.camera_rotation_deg || 0);
  }

  /** What this session may do: the watch-only banner, the login form, the
   * log-out button and the bar's "you are" text. */
  showRights() {
    const w = this.session.state.welcome;
    if (!w) return;
    $('watch-only').hidden = !w.watch_only_reason;
    $('watch-only').textContent = w.watch_only_reason ? `Watch only: ${w.watch_only_reason}` : '';
    $('login').hidden = !(w.password_set && !w.logged_in && !w.pilot);
    $('logout').hidden = !w.logged_in;
    const who = w.sysid != null ? `you are GCS ${w.sysid}` : w.pilot ? 'you may pilot' : 'watching';
    $('me').textContent = `${who}${w.logged_in ? ' (logged in)' : ''}`;
  }

  /** The control-mode radio buttons and the SURFACE button, from the welcome's mode list. */
  showModes(modes, onPickMode) {
    const box = $('control-modes');
    box.querySelectorAll('label.mode').forEach((l) => {
      if (l.nextSibling && l.nextSibling.nodeType === Node.TEXT_NODE) l.nextSibling.remove();
      l.remove();
    });
    const surface = $('surface');
    for (const m of modes) {
      if (m.button) {
        surface.textContent = m.label;
        continue;
      }
      const label = document.createElement('label');
      label.className = 'mode';
      const r = document.createElement('input');
      r.type = 'radio';
      r.name = 'mode';
      r.value = String(m.mode);
      r.checked = m.mode === this.session.currentMode();
      r.addEventListener('change', () => { if (r.checked) onPickMode(m.mode); });
      label.append(r, ` ${m.label}`);
      // The space between inline labels that the static markup had.
      box.insertBefore(label, surface);
      box.insertBefore(document.createTextNode(' '), surface);
    }
    this.labelTouchpad();
  }

  /** The touch buttons' labels for `mode` (default: the vehicle's). */
  labelTouchpad(mode) {
    const manual = this.session.drivesThrusters(mode ?? this.session.currentMode());
    const labels = manual ? KEY_LABELS.manual : KEY_LABELS.motion;
    document.querySelectorAll('#touchpad .tp').forEach((b) => { b.textContent = labels[b.dataset.key]; });
  }

  // ---- telemetry ------------------------------------------------------------

  telemetry(t, prev) {
    $('hdg').textContent = fmt(t.heading_deg, 0);
    $('depth').textContent = fmt(t.depth_m, 2);
    $('armed-state').textContent = t.armed ? 'ARMED' : 'DISARMED';
    $('mode-name').textContent = t.mode_name || '—';
    $('sim-banner').hidden = !t.simulated;
    document.querySelectorAll('input[name=run]').forEach((r) => {
      if (document.activeElement !== r) r.checked = (r.value === 'simulator') === !!t.simulated;
    });
    const h = t.health;
    setPill('link', `board: ${!t.vehicle_seen ? 'no vehicle' : h ? (h.board_link ? 'link up' : 'LINK DOWN') : '—'}`, h && h.board_link && t.vehicle_seen ? 'ok' : 'bad');
    const fs = h && (!h.pilot_input || t.critical);
    setPill('failsafe', `failsafe: ${h ? (fs ? 'ACTIVE' : 'none') : '—'}`, h ? (fs ? 'bad' : 'ok') : '');
    if (t.mode != null && t.mode !== (prev && prev.mode)) {
      document.querySelectorAll('input[name=mode]').forEach((r) => { r.checked = Number(r.value) === t.mode; });
      this.labelTouchpad();
    }
    this.controlOwner(t.control);
    syncSlider('gain', t.gain, (v) => v.toFixed(2));
    syncSlider('lights', t.lights, (v) => String(v));
    if (Number.isFinite(t.tilt)) syncSlider('tilt', (t.tilt - 0.5) * 180, (v) => v.toFixed(0));
    if (t.laser != null && document.activeElement !== $('laser')) $('laser').checked = t.laser;
    const ap = t.autopilot;
    $('ap-depth-now').textContent = ap && ap.depth_target_m != null ? `${ap.depth_target_m.toFixed(1)} m` : 'off';
    $('ap-heading-now').textContent = ap && ap.heading_target_deg != null ? `${ap.heading_target_deg.toFixed(0)}°` : 'off';
    this.derivedLogs(prev, t);
    $('samples').textContent = String(this.recorder.length);
  }

  /** Logger entries for what changed between two telemetry messages. */
  derivedLogs(p, t) {
    if (!p) return;
    const logger = this.logger;
    if (t.gain != null && t.gain !== p.gain) logger.log('gain', `pilot gain ${fmt(t.gain, 2)}`);
    const a = p.thrusters_us;
    const b = t.thrusters_us;
    if (b && (!a || a.port !== b.port || a.vertical !== b.vertical || a.starboard !== b.starboard)) {
      logger.log('thrust_motors', `port ${b.port} µs, vertical ${b.vertical} µs, starboard ${b.starboard} µs`);
    }
    const pa = p.autopilot || {};
    const ta = t.autopilot || {};
    if (ta.depth_target_m !== pa.depth_target_m) logger.log('ap_depth', `depth setpoint ${ta.depth_target_m == null ? 'off' : `${ta.depth_target_m.toFixed(2)} m`}`);
    if (ta.heading_target_deg !== pa.heading_target_deg) logger.log('ap_heading', `heading setpoint ${ta.heading_target_deg == null ? 'off' : `${ta.heading_target_deg.toFixed(1)}°`}`);
    if (t.health && p.health && t.health.board_link !== p.health.board_link) logger.log('board_link', t.health.board_link ? 'board link up' : 'board link DOWN');
    if (t.critical !== p.critical) logger.log('failsafe', t.critical ? 'vehicle critical (failsafe or link down)' : 'vehicle no longer critical');
    if (t.armed !== p.armed) logger.log('stop', t.armed ? 'armed' : 'disarmed');
    if (t.mode !== p.mode) logger.log('stop', `mode ${t.mode_name} (a stop)`);
  }

  /** The attitude indicator, from the latest telemetry (every animation frame). */
  drawAttitude() {
    drawAttitude($('attitude'), this.session.state.t);
  }

  // ---- server messages ------------------------------------------------------

  ack(m) {
    this.message(6, `${m.command_name}: ${m.result_name}`);
    if (m.command_name === 'NEPTUNUS_SET_AUTOPILOT_TARGET' && m.result_name !== 'ACCEPTED') {
      this.logger.log('ap_depth', `target refused: ${m.result_name}`);
    }
  }

  /** A line in the messages list (newest first); `severity` as MAV_SEVERITY. */
  message(severity, text) {
    const li = document.createElement('li');
    li.className = `sev${severity}`;
    li.textContent = `${new Date().toLocaleTimeString()} ${text}`;
    const list = $('messages');
    list.prepend(li);
    while (list.childElementCount > MAX_MESSAGES) list.lastChild.remove();
  }

  // ---- control ----------------------------------------------------------------

  /** Who is in control, from telemetry's `control`. */
  controlOwner(c) {
    const owner = c.owner == null ? 'nobody' : c.you ? `you (GCS ${c.owner})` : `GCS ${c.owner}`;
    setPill('who', `control: ${owner}`, c.you ? 'ok' : c.owner == null ? '' : 'warn');
    $('release').disabled = !c.you;
  }

  /** The server's `control` message: control changed hands. */
  control(c) {
    this.logger.log('control', `in control: ${c.owner == null ? 'nobody' : `GCS ${c.owner}`}${c.you ? ' (you)' : ''}`);
    if (!c.you) this.closeRequest();
  }

  /** Another station asks for control: the prompt, closed after the server's timeout. */
  controlRequest(m) {
    $('request-text').textContent = `GCS ${m.requester} requests control of the vehicle. Hand it over? (${Math.round(m.timeout_s)} s to answer)`;
    const d = $('request-dialog');
    if (!d.open) d.show();
    clearTimeout(this.requestTimer);
    this.requestTimer = setTimeout(() => this.closeRequest(), m.timeout_s * 1000);
    this.logger.log('control', `GCS ${m.requester} requests control`);
  }

  closeRequest() {
    const d = $('request-dialog');
    if (d.open) d.close();
  }

  // ---- video -------------------------------------------------------------------

  applyRotation(deg) {
    this.rotation = deg;
    this.layoutVideo();
  }

  layoutVideo() {
    const img = $('video');
    const box = $('video-box');
    if (this.rotation % 180 === 0) {
      img.style.width = '100%';
      img.style.height = '100%';
    } else {
      // Rotated a quarter turn: the image's box is the container's, transposed.
      img.style.width = `${box.clientHeight}px`;
      img.style.height = `${box.clientWidth}px`;
    }
    img.style.position = 'absolute';
    img.style.left = '50%';
    img.style.top = '50%';
    img.style.transform = `translate(-50%, -50%) rotate(${this.rotation}deg)`;
  }

  async startVideo() {
    const img = $('video');
    img.addEventListener('error', () => { img.hidden = true; $('no-video').hidden = false; $('no-video').textContent = 'No video: the camera stream stopped'; });
    img.addEventListener('load', () => { img.hidden = false; $('no-video').hidden = true; });
    let available = false;
    try {
      const r = await fetch('/api/video');
      available = r.ok && (await r.json()).available;
    } catch { available = false; }
    if (available) {
      img.hidden = false;
      $('no-video').hidden = true;
      img.src = '/video.mjpg';
    }
    window.addEventListener('resize', () => this.layoutVideo());
  }

  // ---- developer interface -------------------------------------------------

  devShown() { return !$('dev').hidden; }
}

function setPill(id, text, cls) {
  const el = $(id);
  el.textContent = text;
  el.className = `pill ${cls || ''}`;
}

/** Follows telemetry, except while the operator holds the slider (focused,
 * or `data-dragging`, which controls.js sets between pointerdown and change). */
function syncSlider(id, v, show) {
  const el = $(id);
  if (v == null || !Number.isFinite(v) || document.activeElement === el || el.dataset.dragging) return;
  el.value = String(v);
  $(`${id}-out`).textContent = show(v);
}

// The operator page's view: renders what the session knows into the DOM —
// the status bar, the HUD's words (armed and mode, battery, who drives,
// failsafe reasons) and its drawing (hud.js), the video's state, the
// alerts (alerts.js), the owner's control-request prompt and the requester's
// waiting note, the rights/login banner, the modes offered by the server,
// and the readouts and sliders that follow telemetry — and writes the
// logger entries that telemetry and server messages imply. Nothing shown
// looks live once its data is older than STALE_MS. Sends nothing: the
// controls do (controls.js). docs/ARCHITECTURE.md is the map of the whole program.
import { KEY_LABELS } from '/js/input.js';
import { drawHud, hudData, STALE_MS } from '/js/hud.js';
import { Alerts } from '/js/alerts.js';

const $ = (id) => document.getElementById(id);
const fmt = (v, d) => (Number.isFinite(v) ? v.toFixed(d) : '—');
/** Video with no new frame for this long is dimmed and marked lost. */
export const VIDEO_LOST_MS = 1000;
/** Battery: the fraction left below which the widget warns, and turns red. */
const BATTERY_LOW_PCT = 30;
const BATTERY_CRITICAL_PCT = 15;
/** The board pill turns amber at this share of the serial line damaged
 * (the link re-sends what the board did not take, but a line this bad
 * wants its cable or connector looked at). */
const LINE_DAMAGE_WARN_PCT = 1;
/** How long a run-mode pick shows before the vehicle's own run mode wins again. */
const RUN_PICK_MS = 3000;

export class View {
  /** `session`: read for the welcome, telemetry and modes (session.js);
   * `video`: the camera picture (video.js); `logger`, `recorder`: the
   * developer interface's (recorder.js). */
  constructor({ session, video, logger, recorder }) {
    this.session = session;
    this.alerts = new Alerts($('messages'), $('alert-badge'), $('speak'));
    this.video = video;
    this.logger = logger;
    this.recorder = recorder;
    this.tAt = null; // performance.now() when the latest telemetry arrived
    this.online = false;
    this.request = null; // the owner's prompt: { requester, deadline }
    this.pending = null; // this page's own request: { owner, deadline }
    this.runPick = null; // a run mode the operator picked: { mode, until }
  }

  /** The operator picked run mode `mode`; the radios keep it until the vehicle answers. */
  pickedRun(mode) {
    this.runPick = { mode, until: performance.now() + RUN_PICK_MS };
  }

  // ---- connection and session --------------------------------------------

  connected() {
    this.online = true;
    setPill('conn', 'connected', 'ok');
    $('disconnected').hidden = true;
    document.body.classList.remove('offline');
    // The vehicle may have restarted: ask for the picture again at once.
    this.video.restart();
  }

  disconnected() {
    this.online = false;
    setPill('conn', 'disconnected — retrying', 'bad');
    $('disconnected').hidden = false;
    document.body.classList.add('offline');
    this.closeRequest();
    this.setPending(null);
  }

  /** `onPickMode(mode)`: called when the operator picks a control mode. */
  welcome(m, onPickMode) {
    this.showModes(m.modes || [], onPickMode);
    this.showRights();
    this.video.rotation = m.camera_rotation_deg || 0;
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
    $('cockpit').hidden = !w.logged_in;
    $('pilot-box').hidden = $('login').hidden && $('logout').hidden && !$('login-note').textContent;
    const who = w.sysid != null ? `you are GCS ${w.sysid}` : w.pilot ? 'you may pilot' : 'watching';
    $('me').textContent = `${who}${w.logged_in ? ' (logged in)' : ''}`;
  }

  /** The control-mode buttons and the SURFACE button, from the welcome's mode list. */
  showModes(modes, onPickMode) {
    const box = $('mode-list');
    box.replaceChildren();
    for (const m of modes) {
      if (m.button) {
        $('surface').textContent = m.label;
        continue;
      }
      const label = document.createElement('label');
      label.className = 'mode';
      label.title = `${m.label} (${m.name} in QGroundControl)`;
      const r = document.createElement('input');
      r.type = 'radio';
      r.name = 'mode';
      r.value = String(m.mode);
      r.checked = m.mode === this.session.currentMode();
      r.addEventListener('change', () => { if (r.checked) onPickMode(m.mode); });
      label.append(r, ` ${m.label}`);
      box.append(label);
    }
    this.labelTouchpad();
  }

  /** The page's words for `mode` (a number), from the server's list. */
  modeLabel(mode, name) {
    const m = this.session.offeredModes().find((x) => x.mode === mode);
    return m ? m.label : name || '—';
  }

  /** The touch buttons' labels for `mode` (default: the vehicle's). */
  labelTouchpad(mode) {
    const manual = this.session.drivesThrusters(mode ?? this.session.currentMode());
    const labels = manual ? KEY_LABELS.manual : KEY_LABELS.motion;
    document.querySelectorAll('#touchpad .tp').forEach((b) => { b.textContent = labels[b.dataset.key]; });
  }

  // ---- telemetry ------------------------------------------------------------

  /** How old the data behind `key` is (ms): the server's age of the message
   * it came from (`ages_ms`) plus the time since this telemetry arrived;
   * Infinity when there is none or the page is offline. */
  ageOf(key, now = performance.now()) {
    const t = this.session.state.t;
    if (!t || this.tAt == null || !this.online) return Infinity;
    const since = now - this.tAt;
    const ages = t.ages_ms;
    if (!ages) return since;
    return ages[key] == null ? Infinity : ages[key] + since;
  }

  telemetry(t, prev) {
    this.tAt = performance.now();
    const label = t.mode == null ? '—' : this.modeLabel(t.mode, t.mode_name);
    $('armed-state').textContent = t.armed ? 'ARMED' : 'DISARMED';
    $('mode-name').textContent = label;
    $('state').className = t.armed ? 'armed' : 'disarmed';
    $('sim-banner').hidden = !t.simulated;
    // The radios show the vehicle's run mode; a pick waits for the
    // vehicle's answer (RUN_PICK_MS at most), then the vehicle's state wins.
    const vehicleRun = t.simulated ? 'simulator' : 'normal';
    const pick = this.runPick;
    if (pick && (pick.mode === vehicleRun || performance.now() > pick.until)) this.runPick = null;
    if (!this.runPick) document.querySelectorAll('input[name=run]').forEach((r) => { r.checked = r.value === vehicleRun; });
    const h = t.health;
    // The serial line's quality beside the link: frames and lines damaged
    // or lost over the last 10 s (a long or wet cable to the board).
    const dropPct = h && h.board_line_drop_pct > 0 ? h.board_line_drop_pct : 0;
    // The colour follows the figure shown (0.96 reads "1.0": amber).
    const shown = dropPct < 10 ? dropPct.toFixed(1) : dropPct.toFixed(0);
    const line = h && h.board_link && dropPct > 0 ? ` · line ${shown} % damaged` : '';
    setPill('link', `board: ${!t.vehicle_seen ? 'no vehicle' : h ? (h.board_link ? 'link up' : 'LINK DOWN') : '—'}${line}`, h && h.board_link && t.vehicle_seen ? (Number(shown) >= LINE_DAMAGE_WARN_PCT ? 'warn' : 'ok') : 'bad');
    $('link').title = h ? `board serial line: ${dropPct.toFixed(2)} % of frames and lines damaged or lost over the last 10 s, ${h.board_line_errors} since the start` : '';
    this.failsafe(t);
    this.battery(t);
    if (t.mode != null && t.mode !== (prev && prev.mode)) {
      document.querySelectorAll('input[name=mode]').forEach((r) => { r.checked = Number(r.value) === t.mode; });
      this.labelTouchpad();
    }
    this.controlOwner(t.control);
    this.armButton(t.armed, !!(t.control && t.control.you));
    syncSlider('gain', t.gain, (v) => v.toFixed(2));
    syncSlider('lights', t.lights, (v) => String(v));
    const tiltDeg = Number.isFinite(t.tilt) ? (t.tilt - 0.5) * 180 : null;
    if (tiltDeg != null) syncSlider('tilt', tiltDeg, (v) => v.toFixed(0));
    if (t.laser != null && document.activeElement !== $('laser')) $('laser').checked = t.laser;
    $('hud-tilt').textContent = `tilt ${tiltDeg == null ? '—' : `${tiltDeg.toFixed(0)}°`}`;
    $('hud-lights').textContent = `lights ${t.lights == null ? '—' : `${Math.round((t.lights / 255) * 100)} %`}`;
    $('hud-gain').textContent = `gain ${fmt(t.gain, 2)}`;
    const ap = t.autopilot;
    $('ap-depth-now').textContent = ap && ap.depth_target_m != null ? `${ap.depth_target_m.toFixed(1)} m` : 'off';
    $('ap-heading-now').textContent = ap && ap.heading_target_deg != null ? `${ap.heading_target_deg.toFixed(0)}°` : 'off';
    this.derivedLogs(prev, t);
    $('samples').textContent = String(this.recorder.length);
  }

  /** The bar's failsafe pill and the HUD's banner with every active reason. */
  failsafe(t) {
    const h = t.health;
    let reasons = Array.isArray(t.failsafes) ? t.failsafes : [];
    if (!Array.isArray(t.failsafes) && h && (!h.pilot_input || t.critical)) {
      reasons = [t.critical ? 'vehicle critical' : 'no pilot input'];
    }
    const active = reasons.length > 0;
    setPill('failsafe', `failsafe: ${h ? (active ? 'ACTIVE' : 'none') : '—'}`, h ? (active ? 'bad' : 'ok') : '');
    $('failsafe').title = reasons.join('; ');
    $('fs-banner').hidden = !active;
    $('fs-banner').textContent = active ? `FAILSAFE: ${reasons.join(' · ')}` : '';
  }

  /** The battery widget: volts, amps and what is left, coloured when low. */
  battery(t) {
    const el = $('battery');
    $('bat-v').textContent = `${fmt(t.voltage_v, 1)} V`;
    $('bat-a').textContent = `${fmt(t.current_a, 1)} A`;
    $('bat-pct').textContent = `${t.battery_pct == null ? '—' : t.battery_pct} %`;
    const pct = t.battery_pct;
    const unhealthy = t.health && !t.health.battery;
    const level = pct != null && pct <= BATTERY_CRITICAL_PCT ? 'critical' : (pct != null && pct <= BATTERY_LOW_PCT) || unhealthy ? 'low' : '';
    el.classList.toggle('low', level === 'low');
    el.classList.toggle('critical', level === 'critical');
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
    if (t.mode !== p.mode) logger.log('stop', `mode ${this.modeLabel(t.mode, t.mode_name)} (a stop)`);
  }

  /** Every animation frame: the HUD drawing, what has gone stale, the video
   * state and the countdowns. */
  frame(now = performance.now()) {
    const t = this.session.state.t;
    drawHud($('hud'), hudData(t, (k) => this.ageOf(k, now)));
    $('state').classList.toggle('stale', this.ageOf('heartbeat', now) > STALE_MS);
    $('battery').classList.toggle('stale', this.ageOf('battery', now) > STALE_MS);
    $('hud-bottom').classList.toggle('stale', !this.online);
    this.videoState(now);
    this.countdowns(now);
  }

  videoState(now) {
    const v = this.video;
    const has = v.available === true && v.frames > 0;
    $('video').hidden = !has;
    $('video-live').hidden = !(has && v.playsLive());
    $('no-video').hidden = has;
    if (!has) {
      $('no-video').textContent = v.available === false ? 'No video: this vehicle has no camera stream'
        : v.available === null && !this.online ? 'No video: the vehicle does not answer' : 'Waiting for the camera…';
    }
    const age = v.frameAgeMs(now);
    const lost = has && age > VIDEO_LOST_MS;
    $('video-box').classList.toggle('lost', lost);
    $('video-lost').hidden = !lost;
    if (lost) $('video-lost').textContent = `VIDEO LOST — last frame ${Math.round(age / 1000)} s ago`;
  }

  // ---- server messages ------------------------------------------------------

  ack(m) {
    this.message(m.result_name === 'ACCEPTED' ? 6 : 4, m.text || `${m.command_name}: ${m.result_name}`);
    if (m.command_name === 'NEPTUNUS_SET_AUTOPILOT_TARGET' && m.result_name !== 'ACCEPTED') {
      this.logger.log('ap_depth', `target refused: ${m.result_name}`);
    }
  }

  /** An alert (alerts.js); `severity` as MAV_SEVERITY; `opts.failsafe`:
   * a failsafe's text (spoken whatever its severity). */
  message(severity, text, opts = {}) {
    this.alerts.add(severity, text, opts);
    // The request's outcome, told by the vehicle to everyone.
    if (this.pending && /refused by GCS/.test(text)) this.setPending(null);
  }

  // ---- control ----------------------------------------------------------------

  /** Who is in control, from telemetry's `control`. */
  controlOwner(c) {
    const owner = c.owner == null ? 'nobody' : c.you ? `you (GCS ${c.owner})` : `GCS ${c.owner}`;
    setPill('who', `control: ${owner}`, c.you ? 'ok' : c.owner == null ? '' : 'warn');
    const hud = $('hud-control');
    hud.textContent = c.you ? 'you are in control' : c.owner == null ? 'nobody in control' : `GCS ${c.owner} in control`;
    hud.classList.toggle('you', !!c.you);
    $('release').disabled = !c.you;
    $('request').disabled = !!c.you;
  }

  /** Arm says what it would do: nothing while armed (STOP disarms) and
   * nothing for a page that is not in control (the vehicle would refuse). */
  armButton(armed, you) {
    const b = $('arm');
    b.textContent = armed ? 'Armed' : 'Arm';
    b.disabled = armed || !you;
    b.title = armed ? 'Armed: STOP disarms'
      : you ? 'Arm the thrusters' : 'Request control first: only the station in control can arm';
  }

  /** The server's `control` message: control changed hands. */
  control(c) {
    this.logger.log('control', `in control: ${c.owner == null ? 'nobody' : `GCS ${c.owner}`}${c.you ? ' (you)' : ''}`);
    if (!c.you) this.closeRequest();
    this.setPending(null);
  }

  /** Another station asks for control: the prompt, closed after the server's
   * timeout. It never takes focus or moves the page (controls.js makes
   * Accept a pointer-only act). */
  controlRequest(m) {
    $('request-text').textContent = `GCS ${m.requester} asks for control of the vehicle. Hand it over?`;
    this.request = { requester: m.requester, deadline: performance.now() + m.timeout_s * 1000 };
    $('request-dialog').hidden = false;
    this.logger.log('control', `GCS ${m.requester} requests control`);
  }

  closeRequest() {
    this.request = null;
    $('request-dialog').hidden = true;
  }

  /** This page's own request waits for the owner's answer (null: not any more). */
  setPending(p) {
    this.pending = p ? { owner: p.owner, deadline: performance.now() + p.timeout_s * 1000 } : null;
    $('request-pending').hidden = !this.pending;
  }

  countdowns(now) {
    if (this.request) {
      const left = Math.ceil((this.request.deadline - now) / 1000);
      if (left <= 0) this.closeRequest();
      else $('request-countdown').textContent = `${left} s`;
    }
    if (this.pending) {
      const left = Math.ceil((this.pending.deadline - now) / 1000);
      if (left <= 0) {
        this.message(4, `GCS ${this.pending.owner} did not answer the control request`);
        this.setPending(null);
      } else {
        $('request-pending').textContent = `Waiting for GCS ${this.pending.owner} to answer your control request (${left} s)`;
      }
    }
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

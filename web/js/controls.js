// The operator page's controls: turns what the operator does into messages
// to the vehicle — the control buttons and the request prompt's answer,
// login and logout, the input, control and run modes, the autopilot
// setpoints, the gain/lights/tilt sliders and the laser, the keyboard and
// touch buttons — and sends the sticks (or
// thrusters) from input.js at 20 Hz. Keeps the thesis' safety rule: stop on
// blur, hidden tab, and input-, control- and run-mode change. Writes the
// feedback next to its own inputs (login note, input note, slider values
// while dragged); everything the server says is rendered by the view
// (view.js). docs/ARCHITECTURE.md is the map of the whole program.
const $ = (id) => document.getElementById(id);
export const SEND_PERIOD_MS = 50; // sticks at 20 Hz

export class Controls {
  /** `session` (session.js) sends; `view` (view.js) shows; `input`
   * (input.js) is the operator's sticks; `logger` is the developer
   * interface's (recorder.js). */
  constructor({ session, view, input, logger }) {
    this.session = session;
    this.view = view;
    this.input = input;
    this.logger = logger;
    this.lastCmd = {}; // latest command sent (for plots and the logger)
    this.wasActive = false;
    this.lastTilt = null;
  }

  bind() {
    this.bindButtons();
    this.bindKeys();
    this.bindTouch();
    this.bindSafety();
  }

  /** Once per welcome: tell the vehicle which input mode is in use (a stop, harmless at start). */
  welcomed() {
    this.session.send({ type: 'input_mode', mode: this.input.mode });
  }

  /** The operator picked control mode `mode` (a number from the server's list). */
  pickMode(mode) {
    this.safetyStop(null);
    this.session.send({ type: 'mode', mode });
    this.view.labelTouchpad(mode);
  }

  /** Sends the current command at 20 Hz: always while in control (the vehicle's
   * pilot-input failsafe expects a steady stream), otherwise only while input is
   * held, and one neutral command on release. */
  tick() {
    const { session, input } = this;
    if (!session.mayPilot()) return;
    const manual = session.drivesThrusters(session.currentMode());
    const cmd = input.command(manual);
    const active = Object.values(cmd).some((v) => v !== 0);
    if (session.inControl() || active || this.wasActive) {
      session.send(manual ? { type: 'thrusters', ...cmd } : { type: 'sticks', ...cmd });
      const changed = JSON.stringify(cmd) !== JSON.stringify(this.lastCmd);
      if (changed) this.logger.log('thrust_client', Object.entries(cmd).map(([k, v]) => `${k} ${v.toFixed(2)}`).join(', '));
      this.lastCmd = cmd;
    }
    this.wasActive = active;
    this.showDriving(cmd, active);
    const tilt = input.headTilt();
    if (tilt != null && (this.lastTilt == null || Math.abs(tilt - this.lastTilt) >= 2)) {
      this.lastTilt = tilt;
      session.send({ type: 'tilt', deg: Math.round(tilt) });
    }
    session.keepAlive();
  }

  /** The driving indicator: what is being sent, and the touch buttons of
   * the keys held lit. */
  showDriving(cmd, active) {
    const el = $('driving');
    el.classList.toggle('active', active);
    $('drive-indicator').textContent = active ? `sending: ${drivingWords(cmd)}` : `${this.input.mode}: idle`;
    document.querySelectorAll('#touchpad .tp').forEach((b) => b.classList.toggle('held', this.input.held.has(b.dataset.key)));
  }

  /** The thesis' safety mode: stop now; the server tells the vehicle why. */
  safetyStop(kind) {
    this.input.releaseAll();
    document.querySelectorAll('#touchpad .tp.held').forEach((b) => b.classList.remove('held'));
    this.lastCmd = {};
    this.wasActive = false;
    if (kind === 'focus') this.session.send({ type: 'focus_lost' });
    else if (kind) this.session.send({ type: 'stop' });
    this.logger.log('stop', kind === 'focus' ? 'window lost focus: stop' : kind === 'stop' ? 'STOP pressed: disarm' : 'stop');
  }

  // ---- login ------------------------------------------------------------------

  /** The login form: POST /api/login sets the login cookie; the WebSocket is
   * then opened again so the new session carries it. */
  async login(password) {
    const note = $('login-note');
    note.textContent = 'checking…';
    note.classList.remove('refused');
    let r;
    let body = {};
    try {
      r = await fetch('/api/login', {
        method: 'POST',
        headers: { 'Content-Type': 'application/json' },
        body: JSON.stringify({ password }),
      });
      body = await r.json();
    } catch {
      note.textContent = 'the vehicle did not answer: try again';
      return;
    }
    note.textContent = body.message || `HTTP ${r.status}`;
    note.classList.toggle('refused', !body.ok);
    this.view.message(body.ok ? 6 : 4, `login: ${note.textContent}`);
    if (body.ok) this.reconnect();
  }

  async logout() {
    try { await fetch('/api/logout', { method: 'POST' }); } catch { /* the reconnect shows the state */ }
    $('login-note').textContent = '';
    this.reconnect();
  }

  reconnect() {
    this.safetyStop(null);
    this.session.reconnect();
  }

  // ---- buttons, forms and sliders ---------------------------------------------

  bindButtons() {
    const { session, input, logger, view } = this;
    const send = (msg) => session.send(msg);
    $('request').onclick = () => { send({ type: 'request_control' }); logger.log('control', 'control requested'); };
    $('release').onclick = () => send({ type: 'release_control' });
    $('arm').onclick = () => send({ type: 'arm', arm: true });
    // STOP: the page lets go of every key and the vehicle disarms (thrusters neutral).
    $('disarm').onclick = () => { this.safetyStop('stop'); send({ type: 'arm', arm: false }); };
    // The owner's answer is a pointer act: a key press (Space, Enter) can
    // never hand the vehicle over, and the buttons never take the focus.
    for (const [id, accept] of [['accept', true], ['refuse', false]]) {
      const b = $(id);
      b.addEventListener('pointerdown', (e) => e.preventDefault());
      b.addEventListener('click', (e) => {
        if (e.detail === 0) return; // a click made by the keyboard
        send({ type: 'answer_request', accept });
        view.closeRequest();
      });
    }
    $('fullscreen').onclick = () => {
      const box = $('video-box');
      if (document.fullscreenElement) document.exitFullscreen?.();
      else box.requestFullscreen?.().catch(() => view.message(4, 'This browser refused full screen'));
    };
    // A button clicked with the pointer gives the focus back, so the next
    // Space or Enter drives nothing by surprise and the keys keep driving.
    // The same for radios, checkboxes and sliders (a focused slider would
    // also stop following the vehicle's value).
    document.addEventListener('click', (e) => {
      if (e.detail === 0) return;
      const a = document.activeElement;
      if (a && (a.tagName === 'BUTTON' || (a.tagName === 'INPUT' && ['radio', 'checkbox', 'range'].includes(a.type)))) a.blur();
    });
    $('login').onsubmit = (e) => {
      e.preventDefault();
      const password = $('password').value;
      $('password').value = '';
      this.login(password);
    };
    $('logout').onclick = () => this.logout();
    document.querySelectorAll('input[name=input]').forEach((r) => r.addEventListener('change', () => {
      if (!r.checked) return;
      input.mode = r.value;
      this.safetyStop(null);
      send({ type: 'input_mode', mode: r.value });
      logger.log('stop', `input mode ${r.value}: stop`);
      $('input-note').textContent = '';
      if (r.value === 'headtracking') input.startHead((n) => { $('input-note').textContent = n; });
      if (r.value === 'gamepad') $('input-note').textContent = input.pad ? input.pad.id : 'press a button on the gamepad';
    }));
    $('surface').onclick = () => {
      this.safetyStop(null);
      const surface = session.offeredModes().find((m) => m.button);
      if (surface) send({ type: 'mode', mode: surface.mode });
    };
    document.querySelectorAll('input[name=run]').forEach((r) => r.addEventListener('change', () => {
      if (!r.checked) return;
      this.safetyStop(null);
      view.pickedRun(r.value);
      send({ type: 'run_mode', mode: r.value });
    }));
    $('ap-form').onsubmit = (e) => {
      e.preventDefault();
      const num = (id, lo, hi) => {
        const v = $(id).value.trim();
        if (v === '') return null;
        const n = Number(v);
        return Number.isFinite(n) && n >= lo && n <= hi ? n : undefined;
      };
      const depth = num('ap-depth', 0, 1000);
      const heading = num('ap-heading', 0, 360);
      // Back to driving: the keys go to the vehicle again, not to the field.
      document.activeElement?.blur?.();
      if (depth === undefined || heading === undefined) { view.message(4, 'Autopilot setpoints: depth 0 to 1000 m, heading 0 to 360°'); return; }
      if (depth === null && heading === null) return;
      send({ type: 'autopilot_target', depth_m: depth, heading_deg: heading });
      if (depth !== null) logger.log('ap_depth', `depth target ${depth} m requested`);
      if (heading !== null) logger.log('ap_heading', `heading target ${heading}° requested`);
    };
    // `data-dragging` keeps the view's telemetry from moving a slider the
    // operator holds (view.js syncSlider).
    const slider = (id, type, key, show, log) => {
      const el = $(id);
      el.addEventListener('pointerdown', () => { el.dataset.dragging = '1'; });
      el.addEventListener('pointerup', () => { delete el.dataset.dragging; });
      el.addEventListener('input', () => { $(`${id}-out`).textContent = show(Number(el.value)); });
      el.addEventListener('change', () => {
        delete el.dataset.dragging;
        send({ type, [key]: Number(el.value) });
        if (log) log(Number(el.value));
      });
    };
    slider('gain', 'gain', 'value', (v) => v.toFixed(2), (v) => logger.log('gain', `gain ${v.toFixed(2)} requested`));
    slider('lights', 'lights', 'level', (v) => String(v));
    slider('tilt', 'tilt', 'deg', (v) => v.toFixed(0));
    $('laser').onchange = () => send({ type: 'laser', on: $('laser').checked });
  }

  // ---- keyboard, touch and the safety events ------------------------------------

  bindKeys() {
    const { input } = this;
    window.addEventListener('keydown', (e) => {
      if (typing(e) && (e.key === 'Escape' || e.key === 'Enter')) {
        // Enter submits the field's form; either way the keys drive again.
        if (e.key === 'Escape') e.target.blur();
        else setTimeout(() => e.target.blur(), 0);
        return;
      }
      if (typing(e) || e.ctrlKey || e.metaKey || e.altKey) return;
      if (input.mode !== 'keyboard' && input.mode !== 'touch') return;
      if (input.press(e.code)) e.preventDefault();
    });
    window.addEventListener('keyup', (e) => input.release(e.code));
  }

  bindTouch() {
    const { input } = this;
    const pad = $('touchpad');
    pad.addEventListener('contextmenu', (e) => e.preventDefault());
    document.querySelectorAll('#touchpad .tp').forEach((b) => {
      const down = (e) => {
        e.preventDefault();
        b.setPointerCapture?.(e.pointerId);
        b.classList.add('held');
        input.press(b.dataset.key);
      };
      const up = () => {
        b.classList.remove('held');
        input.release(b.dataset.key);
      };
      b.addEventListener('pointerdown', down);
      b.addEventListener('pointerup', up);
      b.addEventListener('pointercancel', up);
      b.addEventListener('lostpointercapture', up);
    });
    $('video').addEventListener('contextmenu', (e) => e.preventDefault());
  }

  bindSafety() {
    window.addEventListener('blur', () => this.safetyStop('focus'));
    document.addEventListener('visibilitychange', () => { if (document.visibilityState === 'hidden') this.safetyStop('focus'); });
  }
}

/** The command being sent, in the pilot's words ("forward 100 %, dive 50 %"). */
function drivingWords(cmd) {
  const words = {
    surge: ['forward', 'back'], heave_up: ['rise', 'dive'], yaw: ['turn right', 'turn left'],
    port: ['port fwd', 'port back'], vertical: ['vert. down', 'vert. up'], starboard: ['stbd fwd', 'stbd back'],
  };
  return Object.entries(cmd)
    .filter(([, v]) => v !== 0)
    .map(([k, v]) => `${(words[k] || [k, `-${k}`])[v > 0 ? 0 : 1]} ${Math.round(Math.abs(v) * 100)} %`)
    .join(', ');
}

/** Whether a key press is typing into a field rather than driving. */
function typing(e) {
  const t = e.target;
  return t && (t.tagName === 'INPUT' && t.type !== 'radio' && t.type !== 'checkbox' && t.type !== 'range') || (t && t.tagName === 'SELECT');
}

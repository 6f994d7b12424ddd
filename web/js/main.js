// Neptunus operator interface: one WebSocket session (a ground station
// with its own MAVLink system id on the vehicle), the operator controls
// and the safety rules of the thesis (stop on blur, hidden tab, input-,
// control- and run-mode change).
import { Input, KEY_LABELS } from '/js/input.js';
import { drawAttitude } from '/js/attitude.js';
import { Recorder, Plots, Logger, SIGNALS } from '/js/dev.js';

const $ = (id) => document.getElementById(id);
const SEND_PERIOD_MS = 50; // sticks at 20 Hz
const ALIVE_PERIOD_MS = 500;

const state = {
  ws: null,
  welcome: null,
  t: null, // latest telemetry
  lastCmd: {}, // latest command sent (for plots and the logger)
  wasActive: false,
  lastSent: 0,
  lastTilt: null,
};
const input = new Input();
const recorder = new Recorder();
const logger = new Logger($('log'), $('categories'));
const plots = new Plots($('plots'), recorder, (text) => { $('plot-note').textContent = text; });
// Exposed for the browser tests and for poking around in the console.
window.neptunus = { state, input, recorder, plots, logger };

function send(msg) {
  if (state.ws && state.ws.readyState === WebSocket.OPEN) {
    state.ws.send(JSON.stringify(msg));
    state.lastSent = performance.now();
  }
}

// ---- connection -----------------------------------------------------------

function connect() {
  const proto = location.protocol === 'https:' ? 'wss' : 'ws';
  const ws = new WebSocket(`${proto}://${location.host}/ws`);
  state.ws = ws;
  ws.onopen = () => setPill('conn', 'connected', 'ok');
  ws.onclose = () => {
    state.welcome = null;
    if (state.reconnectNow) {
      // Logged in or out: a new session with the new cookie, at once.
      state.reconnectNow = false;
      connect();
      return;
    }
    setPill('conn', 'disconnected — retrying', 'bad');
    setTimeout(connect, 1000);
  };
  ws.onerror = () => {};
  ws.onmessage = (ev) => {
    let m;
    try { m = JSON.parse(ev.data); } catch { return; }
    handle(m);
  };
}

function handle(m) {
  switch (m.type) {
    case 'welcome': onWelcome(m); break;
    case 'telemetry': onTelemetry(m); break;
    case 'statustext': onStatustext(m); break;
    case 'ack':
      message(6, `${m.command_name}: ${m.result_name}`);
      if (m.command_name === 'NEPTUNUS_SET_AUTOPILOT_TARGET' && m.result_name !== 'ACCEPTED') {
        logger.log('ap_depth', `target refused: ${m.result_name}`);
      }
      break;
    case 'control': onControl(m); break;
    case 'control_request': onControlRequest(m); break;
    case 'identity':
      if (state.welcome) { Object.assign(state.welcome, m); showRights(); }
      break;
    case 'login_result':
      message(m.ok ? 6 : 4, m.message);
      break;
    case 'error': message(4, `server: ${m.message}`); break;
    default: break;
  }
}

function onWelcome(m) {
  state.welcome = m;
  showModes(m.modes || []);
  showRights();
  applyRotation(m.camera_rotation_deg || 0);
  // Tell the vehicle which input mode is in use (a stop, harmless at start).
  send({ type: 'input_mode', mode: input.mode });
}

/** What this session may do: the watch-only banner, the login form, the
 * log-out button and the bar's "you are" text. */
function showRights() {
  const w = state.welcome;
  if (!w) return;
  $('watch-only').hidden = !w.watch_only_reason;
  $('watch-only').textContent = w.watch_only_reason ? `Watch only: ${w.watch_only_reason}` : '';
  $('login').hidden = !(w.password_set && !w.logged_in && !w.pilot);
  $('logout').hidden = !w.logged_in;
  const who = w.sysid != null ? `you are GCS ${w.sysid}` : w.pilot ? 'you may pilot' : 'watching';
  $('me').textContent = `${who}${w.logged_in ? ' (logged in)' : ''}`;
}

/** The login form: POST /api/login sets the login cookie; the WebSocket is
 * then opened again so the new session carries it. */
async function login(password) {
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
  message(body.ok ? 6 : 4, `login: ${note.textContent}`);
  if (body.ok) reconnect();
}

async function logout() {
  try { await fetch('/api/logout', { method: 'POST' }); } catch { /* the reconnect shows the state */ }
  $('login-note').textContent = '';
  reconnect();
}

function reconnect() {
  safetyStop(null);
  state.reconnectNow = true;
  if (state.ws) state.ws.close();
}

// ---- telemetry ------------------------------------------------------------

const fmt = (v, d) => (Number.isFinite(v) ? v.toFixed(d) : '—');

function onTelemetry(t) {
  const prev = state.t;
  state.t = t;
  recorder.add(t, state.lastCmd);
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
    labelTouchpad();
  }
  updateControl(t.control);
  syncSlider('gain', t.gain, (v) => v.toFixed(2));
  syncSlider('lights', t.lights, (v) => String(v));
  if (Number.isFinite(t.tilt)) syncSlider('tilt', (t.tilt - 0.5) * 180, (v) => v.toFixed(0));
  if (t.laser != null && document.activeElement !== $('laser')) $('laser').checked = t.laser;
  const ap = t.autopilot;
  $('ap-depth-now').textContent = ap && ap.depth_target_m != null ? `${ap.depth_target_m.toFixed(1)} m` : 'off';
  $('ap-heading-now').textContent = ap && ap.heading_target_deg != null ? `${ap.heading_target_deg.toFixed(0)}°` : 'off';
  derivedLogs(prev, t);
  $('samples').textContent = String(recorder.length);
}

function derivedLogs(p, t) {
  if (!p) return;
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

function syncSlider(id, v, show) {
  const el = $(id);
  if (v == null || !Number.isFinite(v) || document.activeElement === el || el.dataset.dragging) return;
  el.value = String(v);
  $(`${id}-out`).textContent = show(v);
}

function onStatustext(m) {
  message(m.severity, m.text);
  const text = m.text.toLowerCase();
  if (text.includes('failsafe') || m.severity <= 2) logger.log('failsafe', m.text);
  if (text.includes('board link')) logger.log('board_link', m.text);
  if (text.includes('in control') || text.includes('requests control') || text.includes('refused by')) logger.log('control', m.text);
}

function message(severity, text) {
  const li = document.createElement('li');
  li.className = `sev${severity}`;
  li.textContent = `${new Date().toLocaleTimeString()} ${text}`;
  const list = $('messages');
  list.prepend(li);
  while (list.childElementCount > 100) list.lastChild.remove();
}

// ---- control ----------------------------------------------------------------

function updateControl(c) {
  const owner = c.owner == null ? 'nobody' : c.you ? `you (GCS ${c.owner})` : `GCS ${c.owner}`;
  setPill('who', `control: ${owner}`, c.you ? 'ok' : c.owner == null ? '' : 'warn');
  $('release').disabled = !c.you;
}

function onControl(c) {
  logger.log('control', `in control: ${c.owner == null ? 'nobody' : `GCS ${c.owner}`}${c.you ? ' (you)' : ''}`);
  if (!c.you) closeRequest();
}

let requestTimer = null;
function onControlRequest(m) {
  $('request-text').textContent = `GCS ${m.requester} requests control of the vehicle. Hand it over? (${Math.round(m.timeout_s)} s to answer)`;
  const d = $('request-dialog');
  if (!d.open) d.show();
  clearTimeout(requestTimer);
  requestTimer = setTimeout(closeRequest, m.timeout_s * 1000);
  logger.log('control', `GCS ${m.requester} requests control`);
}

function closeRequest() {
  const d = $('request-dialog');
  if (d.open) d.close();
}

// ---- commands from the page -------------------------------------------------

/** The vehicle's mode number: telemetry's, else the one it starts in (null before the welcome). */
function currentMode() {
  if (state.t && state.t.mode != null) return state.t.mode;
  return state.welcome ? state.welcome.boot_mode : null;
}

/** The modes the server offers (from the welcome); the page knows no mode number. */
function offeredModes() {
  return (state.welcome && state.welcome.modes) || [];
}

/** In this mode the page drives each thruster rather than the sticks. */
function drivesThrusters(mode) {
  return offeredModes().some((m) => m.mode === mode && m.thrusters);
}

/** The control-mode radio buttons and the SURFACE button, from the welcome's mode list. */
function showModes(modes) {
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
    r.checked = m.mode === currentMode();
    r.addEventListener('change', () => {
      if (!r.checked) return;
      safetyStop(null);
      send({ type: 'mode', mode: m.mode });
      labelTouchpad(m.mode);
    });
    label.append(r, ` ${m.label}`);
    // The space between inline labels that the static markup had.
    box.insertBefore(label, surface);
    box.insertBefore(document.createTextNode(' '), surface);
  }
  labelTouchpad();
}

function inControl() {
  return !!(state.t && state.t.control && state.t.control.you);
}

/** Sends the current command at 20 Hz: always while in control (the vehicle's
 * pilot-input failsafe expects a steady stream), otherwise only while input is
 * held, and one neutral command on release. */
function sendTick() {
  if (!state.welcome || !state.welcome.pilot) return;
  const manual = drivesThrusters(currentMode());
  const cmd = input.command(manual);
  const active = Object.values(cmd).some((v) => v !== 0);
  if (inControl() || active || state.wasActive) {
    send(manual ? { type: 'thrusters', ...cmd } : { type: 'sticks', ...cmd });
    const changed = JSON.stringify(cmd) !== JSON.stringify(state.lastCmd);
    if (changed) logger.log('thrust_client', Object.entries(cmd).map(([k, v]) => `${k} ${v.toFixed(2)}`).join(', '));
    state.lastCmd = cmd;
  }
  state.wasActive = active;
  const tilt = input.headTilt();
  if (tilt != null && (state.lastTilt == null || Math.abs(tilt - state.lastTilt) >= 2)) {
    state.lastTilt = tilt;
    send({ type: 'tilt', deg: Math.round(tilt) });
  }
  if (performance.now() - state.lastSent >= ALIVE_PERIOD_MS) send({ type: 'alive' });
}

/** The thesis' safety mode: stop now; the server tells the vehicle why. */
function safetyStop(kind) {
  input.releaseAll();
  document.querySelectorAll('#touchpad .tp.held').forEach((b) => b.classList.remove('held'));
  state.lastCmd = {};
  state.wasActive = false;
  if (kind === 'focus') send({ type: 'focus_lost' });
  else if (kind) send({ type: 'stop' });
  logger.log('stop', kind === 'focus' ? 'window lost focus: stop' : 'stop');
}

function bindControls() {
  $('request').onclick = () => { send({ type: 'request_control' }); logger.log('control', 'control requested'); };
  $('release').onclick = () => send({ type: 'release_control' });
  $('arm').onclick = () => send({ type: 'arm', arm: true });
  $('disarm').onclick = () => send({ type: 'arm', arm: false });
  $('accept').onclick = () => { send({ type: 'answer_request', accept: true }); closeRequest(); };
  $('refuse').onclick = () => { send({ type: 'answer_request', accept: false }); closeRequest(); };
  $('login').onsubmit = (e) => {
    e.preventDefault();
    const password = $('password').value;
    $('password').value = '';
    login(password);
  };
  $('logout').onclick = logout;
  document.querySelectorAll('input[name=input]').forEach((r) => r.addEventListener('change', () => {
    if (!r.checked) return;
    input.mode = r.value;
    safetyStop(null);
    send({ type: 'input_mode', mode: r.value });
    logger.log('stop', `input mode ${r.value}: stop`);
    $('input-note').textContent = '';
    if (r.value === 'headtracking') input.startHead((n) => { $('input-note').textContent = n; });
    if (r.value === 'gamepad') $('input-note').textContent = input.pad ? input.pad.id : 'press a button on the gamepad';
  }));
  $('surface').onclick = () => {
    safetyStop(null);
    const surface = offeredModes().find((m) => m.button);
    if (surface) send({ type: 'mode', mode: surface.mode });
  };
  document.querySelectorAll('input[name=run]').forEach((r) => r.addEventListener('change', () => {
    if (!r.checked) return;
    safetyStop(null);
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
    if (depth === undefined || heading === undefined) { message(4, 'Autopilot: depth 0..1000 m, heading 0..360°'); return; }
    if (depth === null && heading === null) return;
    send({ type: 'autopilot_target', depth_m: depth, heading_deg: heading });
    if (depth !== null) logger.log('ap_depth', `depth target ${depth} m requested`);
    if (heading !== null) logger.log('ap_heading', `heading target ${heading}° requested`);
  };
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
  $('dev-toggle').onclick = () => {
    $('dev').hidden = !$('dev').hidden;
    if (!$('dev').hidden) plots.refresh();
  };
  const sel = $('signal');
  for (const [key, label] of SIGNALS) {
    const o = document.createElement('option');
    o.value = key;
    o.textContent = label;
    sel.append(o);
  }
  $('add-plot').onclick = () => plots.add(sel.value);
  $('remove-plots').onclick = () => plots.removeAll();
  $('reset-data').onclick = () => { recorder.reset(); plots.refresh(); $('samples').textContent = '0'; };
  $('export-csv').onclick = () => {
    const blob = new Blob([recorder.csv()], { type: 'text/csv' });
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob);
    a.download = `neptunus-${new Date().toISOString().replace(/[:.]/g, '-')}.csv`;
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  };
}

// ---- keyboard and touch ----------------------------------------------------

function typing(e) {
  const t = e.target;
  return t && (t.tagName === 'INPUT' && t.type !== 'radio' && t.type !== 'checkbox' && t.type !== 'range') || (t && t.tagName === 'SELECT');
}

function bindKeys() {
  window.addEventListener('keydown', (e) => {
    if (typing(e) || e.ctrlKey || e.metaKey || e.altKey) return;
    if (input.mode !== 'keyboard' && input.mode !== 'touch') return;
    if (input.press(e.code)) e.preventDefault();
  });
  window.addEventListener('keyup', (e) => input.release(e.code));
}

function labelTouchpad(mode) {
  const manual = drivesThrusters(mode ?? currentMode());
  const labels = manual ? KEY_LABELS.manual : KEY_LABELS.motion;
  document.querySelectorAll('#touchpad .tp').forEach((b) => { b.textContent = labels[b.dataset.key]; });
}

function bindTouch() {
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

// ---- video -------------------------------------------------------------------

let rotation = 0;
function applyRotation(deg) {
  rotation = deg;
  layoutVideo();
}

function layoutVideo() {
  const img = $('video');
  const box = $('video-box');
  if (rotation % 180 === 0) {
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
  img.style.transform = `translate(-50%, -50%) rotate(${rotation}deg)`;
}

async function startVideo() {
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
  window.addEventListener('resize', layoutVideo);
}

// ---- safety events and loops ---------------------------------------------

function bindSafety() {
  window.addEventListener('blur', () => safetyStop('focus'));
  document.addEventListener('visibilitychange', () => { if (document.visibilityState === 'hidden') safetyStop('focus'); });
}

function frame() {
  // Polled every animation frame: no gamepad event ordering to go wrong.
  input.pollGamepad();
  drawAttitude($('attitude'), state.t);
  requestAnimationFrame(frame);
}

function setPill(id, text, cls) {
  const el = $(id);
  el.textContent = text;
  el.className = `pill ${cls || ''}`;
}

bindControls();
bindKeys();
bindTouch();
bindSafety();
labelTouchpad();
startVideo();
connect();
setInterval(sendTick, SEND_PERIOD_MS);
setInterval(() => { if (!$('dev').hidden) plots.refresh(); }, 250);
requestAnimationFrame(frame);

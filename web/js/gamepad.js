// The gamepad's buttons and status (its sticks stay input.js's): the side
// panel's Gamepad box — which pad is connected, its axes and buttons live
// — the button-function editor (kept per browser in localStorage,
// ArduSub's default map to start with), the mapped functions themselves,
// and the chord that answers the owner's control-request prompt.
//
// A button acts on its press edge (pressed now, not at the previous
// frame), only while input is Gamepad, this page may pilot, the window has
// the focus and nobody types in a field. What it does is one of the page's
// own HMI messages (arm, mode, gain, lights, tilt, laser, request_control),
// so the vehicle's authority check decides, as for a click. It never
// sends sticks or thrusters. docs/ARCHITECTURE.md is the map of the whole
// program.

const $ = (id) => document.getElementById(id);

export const STORAGE_KEY = 'neptunus.gamepad.buttons.v1';

/** Button names in the browser's standard gamepad mapping (W3C Gamepad). */
const BUTTON_NAMES = [
  'A', 'B', 'X', 'Y', 'LB', 'RB', 'LT', 'RT', 'Back', 'Start', 'L stick', 'R stick',
  'D-pad ↑', 'D-pad ↓', 'D-pad ←', 'D-pad →', 'Guide',
];
const STANDARD_BUTTONS = BUTTON_NAMES.length;
const AXIS_NAMES = ['left X', 'left Y', 'right X', 'right Y'];

/** The owner accepts a control request by holding all of these (LB + RB + A):
 * three buttons, so no single press, however clumsy, hands the vehicle over. */
export const ACCEPT_CHORD = [4, 5, 0];
export const ACCEPT_CHORD_WORDS = 'hold LB + RB and press A';

/**
 * ArduSub's default BTNn_FUNCTION map (reference/ardusub-conventions.md,
 * ardupilot.org/sub/docs/sub-hardware.html) is numbered the way
 * QGroundControl numbers an SDL game controller: 0 A, 1 B, 2 X, 3 Y,
 * 4 Back, 5 Guide, 6 Start, 7/8 stick clicks, 9 LB, 10 RB, 11–14 D-pad
 * up/down/left/right. The browser's standard mapping numbers the same
 * buttons otherwise, so the defaults are kept per physical button: Start
 * arms here as in QGroundControl. ArduSub's shift (Guide) and
 * input_hold_set (right stick click) have no HMI message: left unmapped.
 */
export const ARDUSUB_DEFAULTS = Object.freeze({
  1: 'mode:MANUAL', // B: mode_manual (BTN1)
  2: 'mode:ALT_HOLD', // X: mode_depth_hold (BTN2)
  3: 'mode:STABILIZE', // Y: mode_stabilize (BTN3)
  8: 'disarm', // Back: disarm (BTN4)
  9: 'arm', // Start: arm (BTN6)
  10: 'tilt_centre', // left stick click: mount_center (BTN7)
  4: 'tilt_down', // LB: mount_tilt_down (BTN9)
  5: 'tilt_up', // RB: mount_tilt_up (BTN10)
  12: 'gain_up', // D-pad up: gain_inc (BTN11)
  13: 'gain_down', // D-pad down: gain_dec (BTN12)
  14: 'lights_down', // D-pad left: lights1_dimmer (BTN13)
  15: 'lights_up', // D-pad right: lights1_brighter (BTN14)
});

/** Functions other than modes, in the editor's order. */
const FUNCTIONS = [
  ['none', '—'],
  ['arm', 'Arm'],
  ['disarm', 'Disarm (STOP)'],
  ['gain_up', 'Gain +'],
  ['gain_down', 'Gain −'],
  ['lights_up', 'Lights +'],
  ['lights_down', 'Lights −'],
  ['tilt_up', 'Camera tilt up'],
  ['tilt_down', 'Camera tilt down'],
  ['tilt_centre', 'Camera tilt centre'],
  ['laser', 'Laser on/off'],
  ['request_control', 'Request control'],
];
const FUNCTION_IDS = new Set(FUNCTIONS.map(([id]) => id));
const isFunction = (f) => typeof f === 'string' && (FUNCTION_IDS.has(f) || /^mode:[A-Z0-9_]{1,32}$/.test(f));

// One press's step. The gain's and the tilt's limits are the page's sliders'.
const GAIN_STEP = 0.1;
const LIGHTS_STEP = 32; // 255 / 8: ArduSub's JS_LIGHTS_STEPS default
const TILT_STEP_DEG = 10;
/** A value this page sent is the base of the next press for this long
 * (telemetry may not show it yet), so two quick presses make two steps. */
const SENT_BASE_MS = 1000;

const clamp = (v, lo, hi) => Math.max(lo, Math.min(hi, v));

/** The first connected pad, or null. */
function firstPad() {
  let pads = [];
  try {
    pads = navigator.getGamepads ? navigator.getGamepads() : [];
  } catch {
    return null; // a browser that refuses (permissions policy): no pad
  }
  return Array.from(pads || []).find((g) => g && g.connected) || null;
}

const pressedOf = (p) => Array.from(p.buttons || [], (b) => !!(b && (typeof b === 'object' ? b.pressed : b > 0.5)));

/** The stored map, or ArduSub's when there is none or it is damaged. */
export function loadMap(storage = globalThis.localStorage) {
  let raw = null;
  try {
    raw = storage ? storage.getItem(STORAGE_KEY) : null;
  } catch {
    raw = null; // storage blocked: the defaults, for this page's life
  }
  if (raw == null) return { ...ARDUSUB_DEFAULTS };
  let parsed;
  try {
    parsed = JSON.parse(raw);
  } catch {
    return { ...ARDUSUB_DEFAULTS };
  }
  if (!parsed || typeof parsed !== 'object' || Array.isArray(parsed)) return { ...ARDUSUB_DEFAULTS };
  const map = {};
  for (const [k, f] of Object.entries(parsed)) {
    const i = Number(k);
    if (Number.isInteger(i) && i >= 0 && i < 64 && isFunction(f) && f !== 'none') map[i] = f;
  }
  return map;
}

export class Gamepad {
  /** `session` sends and says what this page may do (session.js); `view`
   * holds the owner's prompt (view.js); `controls` does what the page's
   * own buttons do (controls.js); `input` is the input mode (input.js). */
  constructor({ session, view, controls, input }) {
    this.session = session;
    this.view = view;
    this.controls = controls;
    this.input = input;
    this.map = loadMap();
    this.padId = null; // id of the pad shown; null: none
    this.layout = { count: STANDARD_BUTTONS, mapping: 'standard' }; // the editor's rows
    this.prev = []; // buttons pressed at the previous frame
    this.shown = { buttons: [], axes: [], rows: [] }; // what the DOM shows
    this.sent = {}; // kind -> { v, at }: the latest value sent by a button
    this.chordHint = null;
  }

  bind() {
    $('request-chord').textContent = `Gamepad: ${ACCEPT_CHORD_WORDS} to hand over.`;
    $('pad-reset').onclick = () => {
      try { localStorage.removeItem(STORAGE_KEY); } catch { /* blocked: this page only */ }
      this.map = { ...ARDUSUB_DEFAULTS };
      this.renderMap();
    };
    this.showStatus(null);
  }

  /** The modes arrived (welcome): the editor offers them. */
  welcomed() {
    this.renderMap();
  }

  save() {
    try {
      localStorage.setItem(STORAGE_KEY, JSON.stringify(this.map));
    } catch {
      this.view.message(4, 'This browser does not keep the gamepad map (storage blocked): it lasts until the page closes');
    }
  }

  // ---- every animation frame ------------------------------------------------

  frame() {
    const p = firstPad();
    if (!p) {
      if (this.padId !== null) {
        this.padId = null;
        this.prev = [];
        this.showStatus(null);
      }
      this.showChordHint(false);
      return;
    }
    const pressed = pressedOf(p);
    if (p.id !== this.padId) {
      // A pad that appears (Chromium lists it after its first press) or
      // changes: what is held now was not pressed on this page.
      this.padId = p.id;
      this.prev = pressed;
      this.showStatus(p);
    }
    this.showLive(p, pressed);
    const active = this.mayAct();
    this.showChordHint(active);
    if (active) this.act(pressed);
    this.prev = pressed;
  }

  /** Whether the pad's buttons are the pilot's input now. */
  mayAct() {
    if (this.input.mode !== 'gamepad' || !this.session.mayPilot()) return false;
    if (typeof document.hasFocus === 'function' && !document.hasFocus()) return false;
    const el = document.activeElement;
    if (!el) return true;
    const tag = el.tagName;
    const typing = (tag === 'INPUT' && !['radio', 'checkbox', 'range', 'button'].includes(el.type))
      || tag === 'SELECT' || tag === 'TEXTAREA' || el.isContentEditable;
    return !typing;
  }

  act(pressed) {
    const edge = (i) => pressed[i] && !this.prev[i];
    const prompt = !!this.view.request;
    if (prompt) {
      const now = ACCEPT_CHORD.every((i) => pressed[i]);
      const before = ACCEPT_CHORD.every((i) => this.prev[i]);
      if (now && !before) {
        this.session.send({ type: 'answer_request', accept: true });
        this.view.closeRequest();
        this.view.message(6, `Control handed over with the gamepad (${ACCEPT_CHORD_WORDS})`);
        return;
      }
    }
    for (let i = 0; i < pressed.length; i++) {
      // While the prompt is open the chord's buttons are only the chord.
      if (!edge(i) || (prompt && ACCEPT_CHORD.includes(i))) continue;
      const f = this.map[i];
      if (f && f !== 'none') this.run(f);
    }
  }

  /** Does function `f` with the page's own messages. */
  run(f) {
    const { session, controls } = this;
    const t = session.state.t || {};
    const num = (id) => Number($(id).value);
    if (f.startsWith('mode:')) {
      const m = session.offeredModes().find((x) => `mode:${x.name}` === f);
      if (m) controls.pickMode(m.mode);
      return;
    }
    switch (f) {
      case 'arm':
        session.send({ type: 'arm', arm: true });
        break;
      case 'disarm':
        // As the STOP button: every key let go, then disarm.
        controls.safetyStop('stop');
        session.send({ type: 'arm', arm: false });
        break;
      case 'gain_up':
      case 'gain_down': {
        const base = this.base('gain', Number.isFinite(t.gain) ? t.gain : num('gain'));
        const v = clamp(base + (f === 'gain_up' ? GAIN_STEP : -GAIN_STEP), Number($('gain').min), Number($('gain').max));
        this.send('gain', { type: 'gain', value: Math.round(v * 100) / 100 }, v);
        break;
      }
      case 'lights_up':
      case 'lights_down': {
        const base = this.base('lights', Number.isFinite(t.lights) ? t.lights : num('lights'));
        const v = clamp(base + (f === 'lights_up' ? LIGHTS_STEP : -LIGHTS_STEP), 0, 255);
        this.send('lights', { type: 'lights', level: v }, v);
        break;
      }
      case 'tilt_up':
      case 'tilt_down':
      case 'tilt_centre': {
        const now = Number.isFinite(t.tilt) ? Math.round((t.tilt - 0.5) * 180) : num('tilt');
        const base = this.base('tilt', now);
        const v = f === 'tilt_centre' ? 0 : clamp(base + (f === 'tilt_up' ? TILT_STEP_DEG : -TILT_STEP_DEG), -90, 90);
        this.send('tilt', { type: 'tilt', deg: v }, v);
        break;
      }
      case 'laser': {
        const on = typeof t.laser === 'boolean' ? t.laser : $('laser').checked;
        const v = !this.base('laser', on);
        this.send('laser', { type: 'laser', on: v }, v);
        break;
      }
      case 'request_control':
        session.send({ type: 'request_control' });
        break;
      default:
        break;
    }
  }

  /** The value a step starts from: the one this page just sent, if recent. */
  base(kind, fromVehicle) {
    const s = this.sent[kind];
    return s && performance.now() - s.at < SENT_BASE_MS ? s.v : fromVehicle;
  }

  send(kind, msg, v) {
    this.sent[kind] = { v, at: performance.now() };
    this.session.send(msg);
  }

  // ---- the side panel ---------------------------------------------------------

  showStatus(p) {
    const status = $('pad-status');
    status.textContent = p ? p.id : 'no gamepad: press a button on it';
    status.classList.toggle('muted', !p);
    $('pad-status').title = p ? `mapping: ${p.mapping || 'none (buttons numbered by the browser)'}` : '';
    const axes = $('pad-axes');
    const buttons = $('pad-buttons');
    axes.replaceChildren();
    buttons.replaceChildren();
    this.shown = { buttons: [], axes: [], rows: [] };
    // A pad without buttons (or none) gets the standard pad's rows.
    this.layout = p && p.buttons.length
      ? { count: p.buttons.length, mapping: p.mapping }
      : { count: STANDARD_BUTTONS, mapping: 'standard' };
    if (!p) {
      this.renderMap();
      return;
    }
    p.axes.forEach((_, i) => {
      const a = document.createElement('span');
      a.className = 'pad-axis';
      a.dataset.axis = String(i);
      a.title = `axis ${i}${AXIS_NAMES[i] ? ` (${AXIS_NAMES[i]})` : ''}`;
      a.append(document.createElement('i'));
      axes.append(a);
    });
    p.buttons.forEach((_, i) => {
      const b = document.createElement('span');
      b.className = 'pad-btn';
      b.dataset.button = String(i);
      b.textContent = String(i);
      b.title = buttonName(i, p.mapping);
      buttons.append(b);
    });
    this.renderMap();
  }

  /** Cheap: touches the DOM only where a value changed. */
  showLive(p, pressed) {
    const axes = $('pad-axes').children;
    for (let i = 0; i < axes.length; i++) {
      const v = Math.round(clamp(Number(p.axes[i]) || 0, -1, 1) * 50); // half-percent steps
      if (this.shown.axes[i] === v) continue;
      this.shown.axes[i] = v;
      const fill = axes[i].firstChild;
      fill.style.left = `${50 + Math.min(0, v)}%`;
      fill.style.width = `${Math.abs(v)}%`;
      axes[i].title = `axis ${i}${AXIS_NAMES[i] ? ` (${AXIS_NAMES[i]})` : ''}: ${(v / 50).toFixed(2)}`;
    }
    const dots = $('pad-buttons').children;
    for (let i = 0; i < dots.length; i++) {
      const on = !!pressed[i];
      if (this.shown.buttons[i] === on) continue;
      this.shown.buttons[i] = on;
      dots[i].classList.toggle('on', on);
      const row = this.shown.rows[i];
      if (row) row.classList.toggle('on', on);
    }
  }

  /** The owner's prompt says how the pad accepts — while it can. */
  showChordHint(active) {
    const show = active && !!this.view.request;
    if (show === this.chordHint) return;
    this.chordHint = show;
    $('request-chord').hidden = !show;
  }

  /** The editor: one row per button of the pad (the standard 17 without one). */
  renderMap() {
    const { count, mapping } = this.layout;
    const box = $('pad-map');
    const modes = this.session.offeredModes();
    const modeChoices = modes.map((m) => [`mode:${m.name}`, m.label]);
    const choices = [...FUNCTIONS, ...modeChoices];
    const rows = [];
    for (let i = 0; i < count; i++) {
      const row = document.createElement('label');
      row.className = 'pad-row';
      row.dataset.button = String(i);
      const name = document.createElement('span');
      name.textContent = `${i} · ${buttonName(i, mapping)}`;
      const sel = document.createElement('select');
      sel.dataset.button = String(i);
      const current = this.map[i] || 'none';
      const list = choices.some(([id]) => id === current) ? choices
        // A mode this vehicle does not offer (a map from another vehicle): kept, shown as such.
        : [...choices, [current, `${current.slice(5)} (not offered here)`]];
      const group = document.createElement('optgroup');
      group.label = 'Mode';
      for (const [id, label] of list) {
        const o = document.createElement('option');
        o.value = id;
        o.textContent = label;
        (id.startsWith('mode:') ? group : sel).append(o);
      }
      if (group.childElementCount) sel.append(group);
      sel.value = current;
      sel.addEventListener('change', () => {
        if (sel.value === 'none') delete this.map[i];
        else this.map[i] = sel.value;
        this.save();
        // Back to driving: the pad's buttons are ignored while a field has the focus.
        sel.blur();
      });
      row.append(name, sel);
      rows.push(row);
    }
    box.replaceChildren(...rows);
    this.shown.rows = rows;
    this.shown.buttons = [];
  }
}

/** The standard mapping's name of button `i`; other pads number their own. */
function buttonName(i, mapping) {
  return (mapping === 'standard' && BUTTON_NAMES[i]) || `button ${i}`;
}

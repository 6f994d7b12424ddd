// Operator input: keyboard (thesis table 7.1), touch press-and-hold,
// gamepad (table 7.2, polled every animation frame), head tracking.
// Produces one command at a time; controls.js sends it at 20 Hz.
// docs/ARCHITECTURE.md is the map of the whole program.

export const DEADBAND = 0.1;

// Thesis table 7.1. Motion: surge, heave (NED: positive = down), yaw
// (positive = turn to starboard). Manual: one thruster per key
// (vertical positive = down, as NEPTUNUS_THRUSTERS).
const MOTION_KEYS = {
  KeyW: { surge: 1 }, KeyS: { surge: -1 },
  KeyQ: { heave: 1 }, KeyE: { heave: -1 },
  KeyD: { yaw: 1 }, KeyA: { yaw: -1 },
};
const MANUAL_KEYS = {
  KeyW: { vertical: -1 }, KeyS: { vertical: 1 },
  KeyQ: { port: 1 }, KeyA: { port: -1 },
  KeyE: { starboard: 1 }, KeyD: { starboard: -1 },
};
export const KEY_LABELS = {
  motion: { KeyQ: 'Q · dive', KeyW: 'W · forward', KeyE: 'E · rise', KeyA: 'A · turn left', KeyS: 'S · back', KeyD: 'D · turn right' },
  manual: { KeyQ: 'Q · port fwd', KeyW: 'W · vert. up', KeyE: 'E · stbd fwd', KeyA: 'A · port back', KeyS: 'S · vert. down', KeyD: 'D · stbd back' },
};

/** Rescaled deadband: |v| < d is 0, full deflection is still ±1. */
export function deadband(v, d = DEADBAND) {
  if (!Number.isFinite(v) || Math.abs(v) < d) return 0;
  return Math.sign(v) * Math.min(1, (Math.abs(v) - d) / (1 - d));
}

const clamp = (v) => Math.max(-1, Math.min(1, v));

export class Input {
  constructor() {
    this.held = new Set();     // key codes held (keyboard and touch buttons)
    this.order = [];           // most recent last: the latest wins on conflict
    this.pad = null;           // latest gamepad reading
    this.head = { yaw: 0, pitch: 0, ok: false };
    this.headZero = null;
    this.mode = 'keyboard';
  }

  press(code) {
    if (!(code in MOTION_KEYS)) return false;
    this.held.add(code);
    this.order = this.order.filter((c) => c !== code).concat(code);
    return true;
  }

  release(code) {
    this.held.delete(code);
    this.order = this.order.filter((c) => c !== code);
  }

  releaseAll() {
    this.held.clear();
    this.order = [];
  }

  /** Reads the first connected gamepad (called every animation frame). */
  pollGamepad() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    const p = Array.from(pads || []).find((g) => g && g.connected);
    if (!p) { this.pad = null; return; }
    const ax = (i) => deadband(p.axes[i] ?? 0);
    const btn = (i) => { const b = p.buttons[i]; return b ? deadband(b.value ?? (b.pressed ? 1 : 0)) : 0; };
    this.pad = { ly: ax(1), rx: ax(2), ry: ax(3), lt: btn(6), rt: btn(7), id: p.id };
  }

  /** Keys/touch: the latest key on an axis wins (thesis: the most recent command overwrites). */
  fromKeys(manual) {
    const map = manual ? MANUAL_KEYS : MOTION_KEYS;
    const out = {};
    for (const code of this.order) {
      for (const [axis, v] of Object.entries(map[code] || {})) out[axis] = v;
    }
    return out;
  }

  /**
   * The command now: {surge, heave_up, yaw} in motion modes,
   * {port, vertical, starboard} in manual-thruster mode.
   */
  command(manual) {
    let a = {};
    if (this.mode === 'keyboard' || this.mode === 'touch') {
      a = this.fromKeys(manual);
    } else if (this.mode === 'gamepad' && this.pad) {
      const g = this.pad;
      // Table 7.2: stick up is negative on the Gamepad API's y axes.
      a = manual
        ? { starboard: -g.ry, port: -g.ly, vertical: g.lt - g.rt }
        : { surge: -g.ry, heave: g.ly, yaw: g.rx };
    } else if (this.mode === 'headtracking' && this.head.ok && this.headZero) {
      // Turning the head turns the vehicle: yaw rate from the yaw offset (full at 45°).
      const dyaw = ((this.head.yaw - this.headZero.yaw + 540) % 360) - 180;
      a = manual ? {} : { yaw: deadband(dyaw / 45, 10 / 45) };
    }
    if (manual) {
      return { port: clamp(a.port || 0), vertical: clamp(a.vertical || 0), starboard: clamp(a.starboard || 0) };
    }
    return { surge: clamp(a.surge || 0), heave_up: clamp(-(a.heave || 0)), yaw: clamp(a.yaw || 0) };
  }

  /** Camera tilt from head pitch (degrees, −90..90), or null. */
  headTilt() {
    if (this.mode !== 'headtracking' || !this.head.ok || !this.headZero) return null;
    return Math.max(-90, Math.min(90, this.head.pitch - this.headZero.pitch));
  }

  calibrateHead() {
    if (this.head.ok) this.headZero = { yaw: this.head.yaw, pitch: this.head.pitch };
  }

  /** Starts head tracking: WebXR when the browser has it, else device orientation. */
  async startHead(note) {
    if (navigator.xr && (await navigator.xr.isSessionSupported?.('inline').catch(() => false))) {
      try {
        const session = await navigator.xr.requestSession('inline');
        const space = await session.requestReferenceSpace('viewer');
        const frame = (t, f) => {
          const pose = f.getViewerPose(space);
          if (pose) {
            const q = pose.transform.orientation;
            this.head.yaw = (Math.atan2(2 * (q.w * q.y + q.x * q.z), 1 - 2 * (q.y * q.y + q.x * q.x)) * 180) / Math.PI;
            this.head.pitch = (Math.asin(Math.max(-1, Math.min(1, 2 * (q.w * q.x - q.z * q.y)))) * 180) / Math.PI;
            this.head.ok = true;
            if (!this.headZero) this.calibrateHead();
          }
          session.requestAnimationFrame(frame);
        };
        session.requestAnimationFrame(frame);
        note('WebXR head tracking');
        return;
      } catch {
        // Fall through to device orientation.
      }
    }
    if ('DeviceOrientationEvent' in window) {
      const perm = window.DeviceOrientationEvent.requestPermission;
      if (typeof perm === 'function') {
        try { await perm(); } catch { /* refused: no data will come */ }
      }
      window.addEventListener('deviceorientation', (e) => {
        if (e.alpha == null) return;
        this.head.yaw = -e.alpha;
        this.head.pitch = (e.beta ?? 90) - 90;
        this.head.ok = true;
        if (!this.headZero) this.calibrateHead();
      });
      note('device orientation (tilt the device to look, turn it to yaw)');
      return;
    }
    note('no head tracking in this browser');
  }
}

// What the developer interface shows, recorded from connection on whether
// or not it is open (thesis 7.2): the plottable signals, the sample
// recorder behind the plots and the CSV export, and the logger with its
// categories. Loaded with the operator page, so it must stay small and
// never import the plotting library: the plots (dev.js, uPlot) load when
// the developer view is first opened and draw what this recorded.
// docs/ARCHITECTURE.md is the map of the whole program.

const MAX_ROWS = 72000; // one hour at 20 Hz; the oldest half goes past that

const g = (f) => (t, c) => { const v = f(t, c || {}); return Number.isFinite(v) ? v : null; };
const us = (k) => g((t) => t.thrusters_us && t.thrusters_us[k]);

// Thesis table 7.3, plus estimates, setpoints and simulated states.
export const SIGNALS = [
  ['depth_m', 'Measured depth [m]', g((t) => t.depth_m)],
  ['roll_deg', 'Measured roll [deg]', g((t) => t.roll_deg)],
  ['pitch_deg', 'Measured pitch [deg]', g((t) => t.pitch_deg)],
  ['heading_deg', 'Measured heading [deg]', g((t) => t.heading_deg)],
  ['voltage_v', 'Voltage [V]', g((t) => t.voltage_v)],
  ['current_a', 'Current [A]', g((t) => t.current_a)],
  ['cmd_surge', 'Command surge', g((t, c) => c.surge)],
  ['cmd_heave', 'Command heave (up +)', g((t, c) => c.heave_up)],
  ['cmd_yaw', 'Command yaw', g((t, c) => c.yaw)],
  ['cmd_port', 'Command port thruster', g((t, c) => c.port)],
  ['cmd_vertical', 'Command vertical thruster', g((t, c) => c.vertical)],
  ['cmd_starboard', 'Command starboard thruster', g((t, c) => c.starboard)],
  ['starboard_us', 'Starboard thruster [µs]', us('starboard')],
  ['port_us', 'Port thruster [µs]', us('port')],
  ['vertical_us', 'Vertical thruster [µs]', us('vertical')],
  ['est_depth_m', 'Estimated depth [m]', g((t) => t.estimate && t.estimate.depth_m)],
  ['est_heading_deg', 'Estimated heading [deg]', g((t) => t.estimate && t.estimate.heading_deg)],
  ['est_climb_mps', 'Estimated climb rate [m/s]', g((t) => t.estimate && t.estimate.climb_rate_mps)],
  ['est_yaw_rate_dps', 'Estimated yaw rate [deg/s]', g((t) => t.estimate && t.estimate.yaw_rate_dps)],
  ['est_roll_deg', 'Estimated roll [deg] (attitude)', g((t) => t.roll_deg)],
  ['est_pitch_deg', 'Estimated pitch [deg] (attitude)', g((t) => t.pitch_deg)],
  ['sp_depth_m', 'Setpoint depth [m]', g((t) => t.autopilot && t.autopilot.depth_target_m)],
  ['sp_heading_deg', 'Setpoint heading [deg]', g((t) => t.autopilot && t.autopilot.heading_target_deg)],
  ['ap_heave_out', 'Autopilot heave output', g((t) => t.autopilot && t.autopilot.heave_output)],
  ['ap_yaw_out', 'Autopilot yaw output', g((t) => t.autopilot && t.autopilot.yaw_output)],
  ['sim_x_m', 'Simulated x (north) [m]', g((t) => t.sim && t.sim.north_m)],
  ['sim_y_m', 'Simulated y (east) [m]', g((t) => t.sim && t.sim.east_m)],
  ['sim_z_m', 'Simulated z (depth) [m]', g((t) => t.sim && t.sim.depth_m)],
  ['sim_psi_deg', 'Simulated ψ [deg]', g((t) => t.sim && t.sim.heading_deg)],
  ['sim_u_mps', 'Simulated u [m/s]', g((t) => t.sim && t.sim.surge_mps)],
  ['sim_v_mps', 'Simulated v [m/s]', g((t) => t.sim && t.sim.sway_mps)],
  ['sim_w_mps', 'Simulated w [m/s]', g((t) => t.sim && t.sim.heave_mps)],
  ['sim_r_dps', 'Simulated r [deg/s]', g((t) => t.sim && t.sim.yaw_rate_dps)],
];

/** Headings (0–360°, wrapping at north): plotted unwrapped, so a turn
 * through north is a continuous line rather than a 360° jump. */
export const HEADINGS = new Set(['heading_deg', 'est_heading_deg', 'sp_heading_deg', 'sim_psi_deg']);

export const CATEGORIES = [
  ['gain', 'Gain change'],
  ['thrust_client', 'Thrust command (client)'],
  ['thrust_motors', 'Thrust command (to motors)'],
  ['control', 'Transfer of control'],
  ['ap_depth', 'Autopilot depth'],
  ['ap_heading', 'Autopilot heading'],
  ['stop', 'Stop'],
  ['failsafe', 'Failsafe'],
  ['board_link', 'Board link'],
];

/** A CSV cell: empty when missing; at most 4 decimals, trailing zeros
 * dropped (1500, 0.25, -12.3457): more than the sensors resolve, and no
 * 16-digit float noise. */
export function csvCell(v) {
  if (v == null || !Number.isFinite(v)) return '';
  // n / 1e4 prints as the shortest decimal that reads back as it: ≤ 4 decimals.
  const r = Math.round(v * 1e4) / 1e4;
  return String(r === 0 ? 0 : r);
}

/** Every telemetry sample of every signal since connection (or the last
 * reset), as the vehicle sent it; headings also unwrapped for the plots. */
export class Recorder {
  constructor() {
    this.reset();
  }

  reset() {
    this.time = [];
    /** Raw values, one array per signal (the CSV's columns). */
    this.cols = SIGNALS.map(() => []);
    /** What the plots draw: the raw column itself, or for a heading its
     * unwrapped copy (the first value as sent, then each step the short way
     * round, continuous across north and across gaps). */
    this.plotCols = SIGNALS.map(([key], i) => (HEADINGS.has(key) ? [] : this.cols[i]));
    this.unwrapped = SIGNALS.map(() => null); // per heading: { raw, value } of the latest sample
  }

  get length() {
    return this.time.length;
  }

  /** The raw column of `key` (tests and the console). */
  column(key) {
    return this.cols[SIGNALS.findIndex(([k]) => k === key)] || [];
  }

  add(t, cmd) {
    if (!t || !Number.isFinite(t.t_ms)) return;
    const values = SIGNALS.map(([, , f]) => f(t, cmd));
    // Nothing known yet (no vehicle seen): the recording starts with data,
    // not a row of empty cells. A gap later is kept (empty cells, a break
    // in the plotted line) rather than drawn across.
    if (this.time.length === 0 && values.every((v) => v == null)) return;
    this.time.push(t.t_ms / 1000);
    values.forEach((v, i) => {
      this.cols[i].push(v);
      if (this.plotCols[i] !== this.cols[i]) this.plotCols[i].push(this.unwrap(i, v));
    });
    if (this.time.length > MAX_ROWS) {
      const cut = MAX_ROWS / 2;
      this.time.splice(0, cut);
      this.cols.forEach((c) => c.splice(0, cut));
      this.plotCols.forEach((c, i) => { if (c !== this.cols[i]) c.splice(0, cut); });
    }
  }

  unwrap(i, raw) {
    if (raw == null) return null;
    const last = this.unwrapped[i];
    let value = raw;
    if (last) {
      const step = raw - last.raw;
      value = last.value + step - 360 * Math.round(step / 360);
    }
    this.unwrapped[i] = { raw, value };
    return value;
  }

  /** `t_s` with 3 decimals, then every signal raw (headings 0–360 as the
   * vehicle sent them) with at most 4 decimals, empty where missing. */
  csv() {
    const head = ['t_s'].concat(SIGNALS.map(([k]) => k)).join(',');
    const rows = this.time.map((t, r) => [t.toFixed(3)].concat(this.cols.map((c) => csvCell(c[r]))).join(','));
    return [head].concat(rows).join('\n') + '\n';
  }
}

export class Logger {
  constructor(list, boxes) {
    this.list = list;
    this.enabled = new Set(CATEGORIES.map(([k]) => k));
    this.entries = [];
    for (const [key, label] of CATEGORIES) {
      const l = document.createElement('label');
      const c = document.createElement('input');
      c.type = 'checkbox';
      c.checked = true;
      c.value = key;
      c.dataset.category = key;
      c.addEventListener('change', () => {
        if (c.checked) this.enabled.add(key); else this.enabled.delete(key);
        this.render();
      });
      l.append(c, ` ${label}`);
      boxes.append(l);
    }
  }

  log(category, text) {
    const stamp = new Date().toISOString().slice(11, 23);
    this.entries.push({ category, text: `${stamp} [${category}] ${text}` });
    if (this.entries.length > 1000) this.entries.splice(0, 500);
    if (this.enabled.has(category)) this.append(this.entries[this.entries.length - 1]);
  }

  append(e) {
    const li = document.createElement('li');
    li.dataset.category = e.category;
    li.textContent = e.text;
    this.list.prepend(li);
    while (this.list.childElementCount > 300) this.list.lastChild.remove();
  }

  render() {
    this.list.textContent = '';
    this.entries.filter((e) => this.enabled.has(e.category)).slice(-300).forEach((e) => this.append(e));
  }
}

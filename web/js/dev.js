// Developer interface: recorder of every plottable signal from connection
// on, up to 10 live plots (uPlot), CSV export, and the logger with
// selectable categories (thesis 7.2). docs/ARCHITECTURE.md is the map of
// the whole program.
import uPlot from '/vendor/uPlot.esm.js';

export const MAX_PLOTS = 10;
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

export class Recorder {
  constructor() {
    this.reset();
  }

  reset() {
    this.time = [];
    this.cols = SIGNALS.map(() => []);
  }

  get length() {
    return this.time.length;
  }

  add(t, cmd) {
    this.time.push(t.t_ms / 1000);
    SIGNALS.forEach(([, , f], i) => this.cols[i].push(f(t, cmd)));
    if (this.time.length > MAX_ROWS) {
      const cut = MAX_ROWS / 2;
      this.time.splice(0, cut);
      this.cols.forEach((c) => c.splice(0, cut));
    }
  }

  csv() {
    const head = ['t_s'].concat(SIGNALS.map(([k]) => k)).join(',');
    const rows = this.time.map((t, r) => [t.toFixed(3)].concat(this.cols.map((c) => (c[r] == null ? '' : c[r]))).join(','));
    return [head].concat(rows).join('\n') + '\n';
  }
}

export class Plots {
  constructor(el, recorder, note) {
    this.el = el;
    this.rec = recorder;
    this.note = note;
    this.plots = []; // {key, index, u, box, zoomed}
  }

  add(key) {
    if (this.plots.length >= MAX_PLOTS) {
      this.note(`At most ${MAX_PLOTS} plots at once: remove one before adding another.`);
      return false;
    }
    const index = SIGNALS.findIndex(([k]) => k === key);
    if (index < 0) return false;
    const [, label] = SIGNALS[index];
    const box = document.createElement('div');
    box.className = 'plot';
    box.dataset.signal = key;
    const head = document.createElement('header');
    const title = document.createElement('b');
    title.textContent = label;
    const left = document.createElement('button');
    left.type = 'button';
    left.textContent = '◀';
    left.title = 'Pan left';
    const right = document.createElement('button');
    right.type = 'button';
    right.textContent = '▶';
    right.title = 'Pan right';
    const close = document.createElement('button');
    close.type = 'button';
    close.textContent = '×';
    close.title = 'Remove this plot';
    close.className = 'remove-plot';
    head.append(title, left, right, close);
    const area = document.createElement('div');
    box.append(head, area);
    this.el.append(box);
    const entry = { key, index, box, zoomed: false };
    const width = Math.max(300, (box.clientWidth || 340) - 10);
    entry.u = new uPlot(
      {
        width,
        height: 180,
        scales: { x: { time: false } },
        axes: [{ stroke: '#8fa7bd', grid: { stroke: '#2b4660' } }, { stroke: '#8fa7bd', grid: { stroke: '#2b4660' } }],
        series: [{ label: 't [s]' }, { label, stroke: '#4fc3f7', width: 1.5, spanGaps: false }],
        cursor: { drag: { x: true, y: false } },
        hooks: {
          setSelect: [() => { entry.zoomed = true; }],
        },
      },
      this.data(index),
      area,
    );
    area.addEventListener('dblclick', () => { entry.zoomed = false; this.refresh(); });
    const pan = (dir) => {
      const s = entry.u.scales.x;
      if (s.min == null || s.max == null) return;
      const d = (s.max - s.min) * 0.25 * dir;
      entry.zoomed = true;
      entry.u.setScale('x', { min: s.min + d, max: s.max + d });
    };
    left.addEventListener('click', () => pan(-1));
    right.addEventListener('click', () => pan(1));
    close.addEventListener('click', () => this.remove(entry));
    this.plots.push(entry);
    this.note('');
    return true;
  }

  data(index) {
    return [this.rec.time, this.rec.cols[index]];
  }

  remove(entry) {
    entry.u.destroy();
    entry.box.remove();
    this.plots = this.plots.filter((p) => p !== entry);
  }

  removeAll() {
    [...this.plots].forEach((p) => this.remove(p));
  }

  /** New data into every plot; a zoomed or panned plot keeps its view. */
  refresh() {
    for (const p of this.plots) {
      // uPlot keeps references: hand it fresh array views so it redraws.
      p.u.setData([this.rec.time.slice(), this.rec.cols[p.index].slice()], !p.zoomed);
    }
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

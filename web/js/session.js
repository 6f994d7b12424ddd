// The page's WebSocket session with the vehicle: one ground station with its
// own MAVLink system id. Connects, reconnects, parses the server's JSON
// messages, keeps what they say (the welcome, the latest telemetry) and
// hands each message to whoever listens for its type. Never touches the
// DOM: the view and the controls do (view.js, controls.js; main.js wires
// them). docs/ARCHITECTURE.md is the map of the whole program.

const RETRY_MS = 1000;
/** With nothing else sent for this long, an `alive` tells the vehicle the page is still there. */
const ALIVE_PERIOD_MS = 500;
/** The server's message types the page acts on; anything else is ignored. */
const SERVER_TYPES = new Set([
  'welcome', 'telemetry', 'statustext', 'ack', 'control', 'control_request', 'request_pending', 'identity',
  'login_result', 'error',
]);

export class Session {
  /** `url`: the vehicle's WebSocket (`ws://host/ws`). */
  constructor(url) {
    this.url = url;
    this.state = {
      ws: null,
      welcome: null, // the welcome (and later identity) message; null while disconnected
      t: null, // latest telemetry
      lastSent: 0, // performance.now() of the latest message sent
      reconnectNow: false,
    };
    this.listeners = new Map();
  }

  /** Calls `fn` for every server message of `type` (SERVER_TYPES), plus two
   * of the session's own: `open` (the socket is up) and `down` (it closed;
   * retrying in a second). `telemetry` listeners get the previous telemetry
   * as a second argument; `identity` is only passed on once merged into the
   * welcome. */
  on(type, fn) {
    if (!this.listeners.has(type)) this.listeners.set(type, []);
    this.listeners.get(type).push(fn);
  }

  emit(type, ...args) {
    for (const fn of this.listeners.get(type) || []) fn(...args);
  }

  connect() {
    const ws = new WebSocket(this.url);
    this.state.ws = ws;
    ws.onopen = () => this.emit('open');
    ws.onclose = () => {
      this.state.welcome = null;
      if (this.state.reconnectNow) {
        // Logged in or out: a new session with the new cookie, at once.
        this.state.reconnectNow = false;
        this.connect();
        return;
      }
      this.emit('down');
      setTimeout(() => this.connect(), RETRY_MS);
    };
    ws.onerror = () => {};
    ws.onmessage = (ev) => {
      let m;
      try { m = JSON.parse(ev.data); } catch { return; }
      this.receive(m);
    };
  }

  /** Closes the socket and opens a new one at once (after a login or a
   * logout, so the new session carries the new cookie). */
  reconnect() {
    this.state.reconnectNow = true;
    if (this.state.ws) this.state.ws.close();
  }

  receive(m) {
    if (!SERVER_TYPES.has(m.type)) return;
    switch (m.type) {
      case 'welcome':
        this.state.welcome = m;
        break;
      case 'telemetry': {
        const prev = this.state.t;
        this.state.t = m;
        this.emit('telemetry', m, prev);
        return;
      }
      case 'identity':
        if (!this.state.welcome) return;
        Object.assign(this.state.welcome, m);
        break;
      default:
        break;
    }
    this.emit(m.type, m);
  }

  send(msg) {
    const ws = this.state.ws;
    if (ws && ws.readyState === WebSocket.OPEN) {
      ws.send(JSON.stringify(msg));
      this.state.lastSent = performance.now();
    }
  }

  /** Sends `alive` if nothing else went out for ALIVE_PERIOD_MS. */
  keepAlive() {
    if (performance.now() - this.state.lastSent >= ALIVE_PERIOD_MS) this.send({ type: 'alive' });
  }

  // ---- what the server said, asked the way the page needs it ---------------

  /** Whether this session may send pilot commands at all (from the welcome). */
  mayPilot() {
    return !!(this.state.welcome && this.state.welcome.pilot);
  }

  /** The vehicle's mode number: telemetry's, else the one it starts in (null before the welcome). */
  currentMode() {
    const { t, welcome } = this.state;
    if (t && t.mode != null) return t.mode;
    return welcome ? welcome.boot_mode : null;
  }

  /** The modes the server offers (from the welcome); the page knows no mode number. */
  offeredModes() {
    return (this.state.welcome && this.state.welcome.modes) || [];
  }

  /** In this mode the page drives each thruster rather than the sticks. */
  drivesThrusters(mode) {
    return this.offeredModes().some((m) => m.mode === mode && m.thrusters);
  }

  inControl() {
    const { t } = this.state;
    return !!(t && t.control && t.control.you);
  }
}

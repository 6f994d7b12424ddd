// Neptunus operator interface: the wiring. Creates the session (session.js:
// the WebSocket, no DOM), the view (view.js: renders what the server says)
// and the controls (controls.js: what the operator does, sent at 20 Hz),
// with the input devices (input.js; the gamepad's buttons: gamepad.js),
// snapshot, recording and the logs list (recording.js), opening Cockpit as
// the pilot (cockpit.js) and the developer interface (the
// recorder and logger of recorder.js from connection on; the plots of
// dev.js loaded when the view first opens), and routes each server message
// to whoever shows it. Read this file first; docs/ARCHITECTURE.md is the
// map of the whole program.
import { Input } from '/js/input.js';
import { Recorder, Logger, CATEGORIES, SIGNALS } from '/js/recorder.js';
import { Session } from '/js/session.js';
import { View } from '/js/view.js';
import { Controls, SEND_PERIOD_MS } from '/js/controls.js';
import { Video } from '/js/video.js';
import { Gamepad } from '/js/gamepad.js';
import { Recording } from '/js/recording.js';
import { CockpitLink } from '/js/cockpit.js';

const $ = (id) => document.getElementById(id);
const PLOT_REFRESH_MS = 250;

/** The logger category a status text goes under: the one the vehicle core
 * chose where it wrote the text (`general` texts only reach the message list). */
const LOGGED = new Set(CATEGORIES.map(([key]) => key));
function categoryOf(m) {
  return LOGGED.has(m.category) ? m.category : null;
}

const wsUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`;
const session = new Session(wsUrl);
const input = new Input();
const recorder = new Recorder();
const logger = new Logger($('log'), $('categories'));
const video = new Video($('video'), $('video-live'));
const view = new View({ session, video, logger, recorder });
const controls = new Controls({ session, view, input, logger });
const gamepad = new Gamepad({ session, view, controls, input });
const recording = new Recording({ session, view, video });
const cockpit = new CockpitLink(view);
// Exposed for the browser tests and for poking around in the console
// (`plots` once the developer view has been opened).
window.neptunus = { state: session.state, session, view, controls, input, video, recorder, plots: null, logger, gamepad, recording };

/** The developer view's plots (dev.js with uPlot, ~50 KB compressed): fetched
 * on the first open only. The panel shows once they can be used. */
let plots = null;
let loading = null;
async function toggleDev() {
  const panel = $('dev');
  if (!panel.hidden) {
    panel.hidden = true;
    $('dev-toggle').setAttribute('aria-expanded', 'false');
    return;
  }
  if (!plots) {
    loading ||= import('/js/dev.js').then((m) => m.bindPlots(recorder));
    try {
      plots = await loading;
      window.neptunus.plots = plots;
    } catch (e) {
      loading = null; // a press retries
      $('plot-note').textContent = `The plots could not be loaded (${e.message}): press Developer again to retry.`;
    }
  }
  panel.hidden = false;
  $('dev-toggle').setAttribute('aria-expanded', 'true');
  if (plots) plots.refresh();
  // It opens below the operator screen: bring it into view.
  panel.scrollIntoView({ block: 'start' });
}
$('dev-toggle').onclick = toggleDev;
// The signal list is the recorder's: there at once, the plots or not.
for (const [key, label] of SIGNALS) $('signal').append(new Option(label, key));

// Every server message, and who acts on it.
session.on('open', () => view.connected());
session.on('down', () => view.disconnected());
session.on('welcome', (m) => {
  view.welcome(m, (mode) => controls.pickMode(mode));
  controls.welcomed();
  gamepad.welcomed();
  recording.listLogs();
  recording.listRecordings();
});
session.on('telemetry', (t, prev) => {
  recorder.add(t, controls.lastCmd);
  view.telemetry(t, prev);
  recording.telemetry(t);
});
session.on('statustext', (m) => {
  view.message(m.severity, m.text, { failsafe: m.category === 'failsafe' });
  const category = categoryOf(m);
  if (category) logger.log(category, m.text);
});
session.on('ack', (m) => view.ack(m));
session.on('control', (m) => view.control(m));
session.on('control_request', (m) => view.controlRequest(m));
session.on('request_pending', (m) => view.setPending(m));
session.on('identity', () => { view.showRights(); recording.listLogs(); recording.listRecordings(); });
session.on('login_result', (m) => view.message(m.ok ? 6 : 4, m.message));
session.on('error', (m) => view.message(4, `server: ${m.message}`));

function frame() {
  // Polled every animation frame: no gamepad event ordering to go wrong.
  input.pollGamepad();
  gamepad.frame();
  view.frame();
  requestAnimationFrame(frame);
}

controls.bind();
gamepad.bind();
recording.bind();
cockpit.bind();
view.labelTouchpad();
video.start();
session.connect();
setInterval(() => controls.tick(), SEND_PERIOD_MS);
setInterval(() => { if (plots && view.devShown()) plots.refresh(); }, PLOT_REFRESH_MS);
requestAnimationFrame(frame);

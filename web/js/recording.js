// Keeping what the pilot sees: the snapshot button (the video canvas as a
// JPEG named with the time and the depth on the HUD), the browser's record
// button (the displayed video — the canvas video.js draws — recorded in the
// browser as WebM with MediaRecorder, with a REC indicator and the time,
// downloaded on stop), the vehicle's record button (ROV: recording on the
// vehicle, asked of the vehicle's camera over MAVLink like any station's
// record button — the server turns `record` into VIDEO_START/STOP_CAPTURE
// and the vehicle decides; its state comes back in telemetry's
// `recording`), and the side panel's lists of the vehicle's logs (GET
// /api/logs) and recordings (GET /api/recordings), each file a download
// link. The lists are shown only to a page that may pilot, which is who the
// server lets read them. docs/ARCHITECTURE.md is the map of the whole
// program.
import { hudData, STALE_MS } from '/js/hud.js';

const $ = (id) => document.getElementById(id);
const JPEG_QUALITY = 0.92;
/** Frames per second asked of the canvas stream (the camera rarely gives more). */
const RECORD_FPS = 30;
/** MediaRecorder hands over data this often, so a long recording is not one huge buffer at stop. */
const RECORD_SLICE_MS = 1000;
const WEBM_TYPES = ['video/webm;codecs=vp9', 'video/webm;codecs=vp8', 'video/webm'];
const KINDS = { tlogs: 'Telemetry logs (tlog)', events: 'Event logs' };

/** "2026-11-25T14-03-12Z": UTC, safe in a file name on every system. */
export function fileStamp(d = new Date()) {
  return `${d.toISOString().slice(0, 19).replace(/:/g, '-')}Z`;
}

/** "depth-1.52m", "depth-unknown" when the HUD has no live depth. */
export function depthTag(depth, fresh) {
  return Number.isFinite(depth) && fresh ? `depth-${depth.toFixed(2)}m` : 'depth-unknown';
}

/** "512 B", "3.4 KiB", "12.0 MiB". */
export function sizeText(bytes) {
  if (!Number.isFinite(bytes) || bytes < 0) return '—';
  if (bytes < 1024) return `${bytes} B`;
  if (bytes < 1024 * 1024) return `${(bytes / 1024).toFixed(1)} KiB`;
  if (bytes < 1024 * 1024 * 1024) return `${(bytes / (1024 * 1024)).toFixed(1)} MiB`;
  return `${(bytes / (1024 * 1024 * 1024)).toFixed(2)} GiB`;
}

/** mm:ss (h:mm:ss past an hour). */
function elapsedText(ms) {
  const s = Math.floor(ms / 1000);
  const hh = Math.floor(s / 3600);
  const mm = Math.floor((s % 3600) / 60);
  const ss = String(s % 60).padStart(2, '0');
  return hh > 0 ? `${hh}:${String(mm).padStart(2, '0')}:${ss}` : `${mm}:${ss}`;
}

/** Saves `blob` as `name` through the browser's downloads. */
function download(blob, name) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

export class Recording {
  /** `session`: the telemetry (depth) and what this page may do; `view`:
   * its messages list and the telemetry ages; `video`: the picture (video.js). */
  constructor({ session, view, video }) {
    this.session = session;
    this.view = view;
    this.video = video;
    this.recorder = null; // { rec, chunks, startedAt, stamp, timer }
    this.vehicleOn = false; // the vehicle records (its last capture status)
  }

  bind() {
    $('snapshot').onclick = () => this.snapshot();
    $('record').onclick = () => (this.recorder ? this.stop() : this.start());
    $('vehicle-record').onclick = () => this.toggleVehicle();
    $('logs-refresh').onclick = () => this.listLogs();
    $('recordings-refresh').onclick = () => this.listRecordings();
    if (!recorderType()) {
      $('record').disabled = true;
      $('record').title = 'This browser cannot record video (no WebM MediaRecorder)';
    }
    // Leaving the page drops a recording not yet downloaded: ask first.
    window.addEventListener('beforeunload', (e) => {
      if (!this.recorder) return;
      e.preventDefault();
      e.returnValue = ''; // older browsers ask only with a returnValue
    });
  }

  /** A picture is on screen. */
  hasPicture() {
    return this.video.available === true && this.video.frames > 0;
  }

  snapshot() {
    if (!this.hasPicture()) {
      this.view.message(4, 'Snapshot: there is no picture to save');
      return;
    }
    // The depth the HUD shows (the estimate when valid), if it is live.
    const d = hudData(this.session.state.t, (k) => this.view.ageOf(k));
    const name = `neptunus-${fileStamp()}-${depthTag(d && d.depth, d && d.depthAge <= STALE_MS)}.jpg`;
    const still = this.video.still();
    if (!still) {
      this.view.message(4, 'Snapshot: there is no picture to save');
      return;
    }
    still.toBlob((blob) => {
      if (!blob) {
        this.view.message(4, 'Snapshot: the browser could not make a JPEG of the picture');
        return;
      }
      download(blob, name);
      this.view.message(6, `Snapshot saved: ${name}`);
    }, 'image/jpeg', JPEG_QUALITY);
  }

  start() {
    const type = recorderType();
    if (!type) {
      this.view.message(4, 'This browser cannot record video (no WebM MediaRecorder)');
      return;
    }
    if (!this.hasPicture()) {
      this.view.message(4, 'Record: there is no picture to record');
      return;
    }
    // WebRTC's pictures are drawn on the canvas, too, while it records.
    if (!this.video.still()) {
      this.view.message(4, 'Record: there is no picture to record');
      return;
    }
    let rec;
    try {
      const stream = this.video.canvas.captureStream(RECORD_FPS);
      rec = new MediaRecorder(stream, { mimeType: type });
    } catch (e) {
      this.view.message(4, `Record: the browser refused to record (${e.message})`);
      return;
    }
    const r = { rec, chunks: [], startedAt: performance.now(), stamp: fileStamp(), timer: null };
    rec.ondataavailable = (e) => { if (e.data && e.data.size > 0) r.chunks.push(e.data); };
    rec.onstop = () => {
      rec.stream.getTracks().forEach((tr) => tr.stop());
      const secs = Math.round((performance.now() - r.startedAt) / 1000);
      const blob = new Blob(r.chunks, { type: 'video/webm' });
      if (blob.size === 0) {
        this.view.message(4, 'Record: nothing was recorded (no new frames)');
        return;
      }
      const name = `neptunus-${r.stamp}-${secs}s.webm`;
      download(blob, name);
      this.view.message(6, `Recording saved: ${name}`);
    };
    rec.onerror = (e) => {
      this.view.message(4, `Record: the recording stopped (${e.error?.message || 'browser error'})`);
      if (this.recorder === r) this.stop();
    };
    rec.start(RECORD_SLICE_MS);
    this.video.mirror = true;
    this.recorder = r;
    r.timer = setInterval(() => this.showRecording(), 250);
    this.showRecording();
  }

  stop() {
    const r = this.recorder;
    if (!r) return;
    this.recorder = null;
    this.video.mirror = false;
    clearInterval(r.timer);
    if (r.rec.state !== 'inactive') r.rec.stop();
    this.showRecording();
  }

  showRecording() {
    const r = this.recorder;
    const b = $('record');
    b.classList.toggle('recording', !!r);
    b.setAttribute('aria-pressed', String(!!r));
    b.title = r ? 'Stop recording and download the video' : 'Record the video (WebM, downloaded on stop)';
    $('rec-indicator').hidden = !r;
    if (r) $('rec-time').textContent = elapsedText(performance.now() - r.startedAt);
  }

  // ---- recording on the vehicle -------------------------------------------

  /** Asks the vehicle to start or stop recording (its camera answers with
   * an ack, and telemetry's `recording` follows). */
  toggleVehicle() {
    this.session.send({ type: 'record', on: !this.vehicleOn });
  }

  /** Whether this page may press the vehicle's record button: a pilot's
   * page, with nobody else in control (the vehicle refuses others). */
  mayRecordOnVehicle(t) {
    const c = t && t.control;
    return this.session.mayPilot() && !!c && (c.you || c.owner == null);
  }

  /** Telemetry came: the vehicle's record button and indicator follow it. */
  telemetry(t) {
    const r = t && t.recording;
    const on = !!(r && r.on);
    const b = $('vehicle-record');
    const may = this.mayRecordOnVehicle(t);
    b.disabled = !r || !r.can || !may;
    b.classList.toggle('recording', on);
    b.setAttribute('aria-pressed', String(on));
    b.title = !(r && r.can) ? 'Recording on the vehicle: the vehicle has no camera that records'
      : !this.session.mayPilot() ? 'Recording on the vehicle is for the pilot: log in first'
        : !may ? 'Recording on the vehicle: only the station in control may start or stop it'
          : on ? 'Stop recording on the vehicle'
            : `Record on the vehicle (H.264 and telemetry, kept on the ROV${r.available_mib > 0 ? `; room for ${sizeText(r.available_mib * 1024 * 1024)}` : ''})`;
    $('vrec-indicator').hidden = !on;
    if (on) $('vrec-time').textContent = elapsedText(r.time_ms || 0);
    if (this.vehicleOn && !on) this.listRecordings();
    this.vehicleOn = on;
  }

  // ---- the vehicle's logs -------------------------------------------------

  /** Asks the vehicle for one of the pilot's lists (`url`) when this page
   * may read it (the server lets only a page that may pilot: logged in, or
   * an address `open_control` admits), saying what happens in `note`. The
   * answer's JSON, or null when there is none to show (`list` is then
   * emptied where the vehicle refused). */
  async fetchPilotList(url, what, note, list) {
    if (!this.session.mayPilot()) {
      list.replaceChildren();
      note.textContent = this.session.state.welcome
        ? `The ${what} are for the pilot: log in with the pilot password to list and download them.`
        : 'Not connected.';
      return null;
    }
    note.textContent = 'asking…';
    try {
      const r = await fetch(url, { cache: 'no-store' });
      if (!r.ok) {
        const why = await r.json().then((j) => j.error).catch(() => null);
        note.textContent = why || `the vehicle refused: HTTP ${r.status}`;
        list.replaceChildren();
        return null;
      }
      return await r.json();
    } catch {
      note.textContent = 'the vehicle did not answer: try again';
      return null;
    }
  }

  /** Lists the logs, when this page may read them. */
  async listLogs() {
    const note = $('logs-note');
    const list = $('logs-list');
    const body = await this.fetchPilotList('/api/logs', 'logs', note, list);
    if (body === null) return;
    const logs = Array.isArray(body && body.logs) ? body.logs : [];
    const items = [];
    for (const [kind, title] of Object.entries(KINDS)) {
      const these = logs.filter((l) => l.kind === kind && typeof l.url === 'string' && l.url.startsWith('/api/logs/'))
        .sort((x, y) => (y.modified_unix_s || 0) - (x.modified_unix_s || 0));
      if (these.length === 0) continue;
      const head = document.createElement('li');
      head.className = 'logs-kind';
      head.textContent = title;
      items.push(head);
      for (const l of these) {
        const li = document.createElement('li');
        const a = document.createElement('a');
        a.href = l.url;
        a.download = l.name;
        a.textContent = l.name;
        const size = document.createElement('span');
        size.className = 'muted';
        const when = l.modified_unix_s ? new Date(l.modified_unix_s * 1000).toLocaleString() : '';
        size.textContent = ` ${sizeText(l.bytes)}${when ? ` · ${when}` : ''}`;
        li.append(a, size);
        items.push(li);
      }
    }
    list.replaceChildren(...items);
    note.textContent = items.length ? `${logs.length} file${logs.length === 1 ? '' : 's'}, newest first` : 'No logs on the vehicle yet.';
  }

  /** Lists the recordings made on the vehicle, grouped by recording, when
   * this page may read them (as the logs). */
  async listRecordings() {
    const note = $('recordings-note');
    const list = $('recordings-list');
    const body = await this.fetchPilotList('/api/recordings', 'recordings', note, list);
    if (body === null) return;
    const files = (Array.isArray(body && body.recordings) ? body.recordings : [])
      .filter((f) => typeof f.url === 'string' && f.url.startsWith('/api/recordings/') && typeof f.recording === 'string');
    const byRecording = new Map();
    for (const f of files) {
      if (!byRecording.has(f.recording)) byRecording.set(f.recording, []);
      byRecording.get(f.recording).push(f);
    }
    const LABEL = { video: (f) => `video ${f.name.slice(-6, -3)}`, subtitles: (f) => `subtitles ${f.name.slice(-7, -4)}`, telemetry: () => 'telemetry CSV' };
    const items = [];
    for (const [rec, these] of [...byRecording].sort((a, b) => (a[0] < b[0] ? 1 : -1))) {
      const li = document.createElement('li');
      const head = document.createElement('div');
      const bytes = these.reduce((n, f) => n + (f.bytes || 0), 0);
      const name = document.createElement('strong');
      name.textContent = rec;
      const size = document.createElement('span');
      size.className = 'muted';
      size.textContent = ` ${sizeText(bytes)}`;
      head.append(name, size);
      const links = document.createElement('div');
      links.className = 'rec-files';
      for (const f of these) {
        const a = document.createElement('a');
        a.href = f.url;
        a.download = f.name;
        a.textContent = (LABEL[f.kind] || (() => f.name))(f);
        a.title = `${f.name} · ${sizeText(f.bytes)}`;
        links.append(a);
      }
      li.append(head, links);
      items.push(li);
    }
    list.replaceChildren(...items);
    note.textContent = items.length
      ? `${items.length} recording${items.length === 1 ? '' : 's'}, newest first (MPEG-TS video, WebVTT subtitles, CSV telemetry)`
      : 'No recordings on the vehicle yet: press ROV on the picture to record there.';
  }
}

function recorderType() {
  if (typeof MediaRecorder === 'undefined' || !HTMLCanvasElement.prototype.captureStream) return null;
  return WEBM_TYPES.find((t) => MediaRecorder.isTypeSupported(t)) || null;
}

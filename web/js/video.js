// The camera picture: over WebRTC when the vehicle offers it (webrtc.js:
// H.264 decoded by the browser, lighter on the tether), else from the
// vehicle's MJPEG stream (/video.mjpg) read with fetch. MJPEG shows the
// first picture while WebRTC connects and stops at WebRTC's first frame; it
// takes over again by itself when WebRTC fails or stalls. Either way the page knows when each frame arrived,
// shows it rotated as the camera is mounted, and starts the stream again
// by itself when it stops or the vehicle comes back. MJPEG pictures are
// drawn on a canvas; WebRTC's are shown by their own <video>, over the
// canvas, as the browser composites them: drawing each on the canvas would
// cost the page's thread a colour conversion per frame and show only the
// frames it found time for. The canvas is what a snapshot saves and a
// recording records: a WebRTC picture is drawn on it for a snapshot, and
// every one while a recording runs. No DOM outside the canvas and the
// <video> it is given. docs/ARCHITECTURE.md is the map of the whole program.

import { WebRtcVideo } from '/js/webrtc.js';

/** A stream that delivers nothing for this long is started again. */
const RESTART_AFTER_MS = 3000;
/** A WebRTC session with no picture this long after it began is given up
 * for MJPEG (ICE and DTLS take well under a second on a tether). */
const WEBRTC_FIRST_FRAME_MS = 6000;
const RETRY_MS = 1000;
/** A part header larger than this is not a part header: resynchronise. */
const MAX_HEADER = 1024;

export class Video {
  /** `canvas`: where MJPEG frames are drawn; `live`: the <video> that
   * shows WebRTC (laid over the canvas, hidden until its first frame);
   * `onState()`: called when the stream becomes available or unavailable
   * (the view reads `available`). */
  constructor(canvas, live, onState = () => {}) {
    this.canvas = canvas;
    this.live = live;
    this.onState = onState;
    this.turn = 0;
    /** Every WebRTC frame is also drawn on the canvas (a recording runs). */
    this.mirror = false;
    this.available = null; // null: not asked yet; false: the vehicle has no camera
    this.lastFrameAt = null; // performance.now() of the latest frame drawn
    this.frames = 0;
    this.abort = null;
    this.running = false;
    this.transport = null; // 'webrtc' or 'mjpeg', once a frame came
    this.webrtc = null; // the WebRTC session while one runs
    this.webrtcStartedAt = null;
    this.webrtcEnded = null; // resolves when that session ends
    this.webrtcFailed = null; // why WebRTC was given up (MJPEG until the vehicle comes back)
  }

  /** The camera's mounting, in degrees clockwise (0, 90, 180, 270). */
  get rotation() {
    return this.turn;
  }

  set rotation(deg) {
    this.turn = deg;
    this.orient();
  }

  /** Turns the <video> as the camera is mounted. A quarter turn swaps its
   * box's sides first, so the turned picture fits the box as the canvas's
   * does. */
  orient() {
    const el = this.live;
    const quarter = this.turn % 180 !== 0;
    const box = el.parentElement;
    const [w, h] = quarter && box ? [box.clientWidth, box.clientHeight] : [0, 0];
    Object.assign(el.style, quarter
      ? { width: `${h}px`, height: `${w}px`, left: `${(w - h) / 2}px`, top: `${(h - w) / 2}px` }
      : { width: '', height: '', left: '', top: '' });
    el.style.transform = this.turn ? `rotate(${this.turn}deg)` : '';
  }

  /** Milliseconds since the latest frame (Infinity before the first). */
  frameAgeMs(now = performance.now()) {
    return this.lastFrameAt == null ? Infinity : now - this.lastFrameAt;
  }

  /** Starts reading, and keeps the stream going for the page's lifetime. */
  start() {
    if (this.running) return;
    this.running = true;
    // A quarter-turned <video> follows its box's size.
    if (typeof ResizeObserver !== 'undefined' && this.live.parentElement) {
      new ResizeObserver(() => { if (this.turn % 180 !== 0) this.orient(); }).observe(this.live.parentElement);
    }
    this.loop();
    // A stream that stalls without closing (a network hiccup) is restarted;
    // WebRTC that gives no picture is given up for MJPEG.
    setInterval(() => {
      const now = performance.now();
      const w = this.webrtc;
      if (w && now - this.webrtcStartedAt > WEBRTC_FIRST_FRAME_MS
        && (this.transport !== 'webrtc' || this.frameAgeMs(now) > RESTART_AFTER_MS)) {
        w.end(this.transport === 'webrtc' ? 'the WebRTC picture stopped' : 'no picture over WebRTC');
      } else if (this.abort && this.frameAgeMs(now) > RESTART_AFTER_MS && this.streamAgeMs() > RESTART_AFTER_MS) {
        this.abort.abort();
      }
    }, 500);
  }

  /** Starts the stream again at once (the vehicle came back): WebRTC is
   * tried again. A WebRTC session still running is on the live vehicle
   * (a restarted one closes its signalling), so it goes on. */
  restart() {
    this.webrtcFailed = null;
    if (this.abort) this.abort.abort();
  }

  streamAgeMs() {
    return this.openedAt == null ? Infinity : performance.now() - this.openedAt;
  }

  async loop() {
    for (;;) {
      try {
        const r = await fetch('/api/video', { cache: 'no-store' });
        const info = r.ok ? await r.json() : {};
        const available = info.available === true;
        this.setAvailable(available);
        if (available && info.webrtc && !this.webrtc && this.webrtcFailed === null) {
          await this.startWebRtc(info.webrtc);
        }
        // A camera that streams H.264 gives no JPEG pictures: WebRTC only.
        const mjpeg = info.mjpeg !== false;
        if (available && this.webrtc && (this.transport === 'webrtc' || !mjpeg)) await this.webrtcEnded;
        else if (available && mjpeg) await this.read();
      } catch {
        // The vehicle is not answering: try again shortly.
      }
      await new Promise((res) => setTimeout(res, RETRY_MS));
    }
  }

  setAvailable(a) {
    if (a !== this.available) {
      this.available = a;
      this.onState();
    }
  }

  /** Starts a WebRTC session (described at `url`) beside the MJPEG
   * stream; its first frame stops MJPEG. Nothing when the vehicle lists no
   * stream. */
  async startWebRtc(url) {
    if (typeof RTCPeerConnection === 'undefined') {
      this.webrtcFailed = 'this browser has no WebRTC';
      return;
    }
    const r = await fetch(url, { cache: 'no-store' });
    const info = r.ok ? await r.json() : {};
    if (!info.streams || !info.streams.length) return;
    let ended;
    this.webrtcEnded = new Promise((resolve) => { ended = resolve; });
    const w = new WebRtcVideo({
      video: this.live,
      iceServers: info.ice_servers || [],
      onFrame: (video, width, height) => {
        if (this.mirror) this.paint(video, width, height);
        this.shown('webrtc', width, height);
        if (this.abort) this.abort.abort();
      },
      onEnd: (reason) => {
        this.webrtc = null;
        this.webrtcFailed = reason;
        console.info(`video: WebRTC ended (${reason}); MJPEG instead`);
        ended();
      },
    });
    this.webrtc = w;
    this.webrtcStartedAt = performance.now();
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    w.start(`${scheme}://${location.host}${info.path}`);
  }

  /** Reads one /video.mjpg response until it ends or is aborted. */
  async read() {
    const abort = new AbortController();
    this.abort = abort;
    this.openedAt = performance.now();
    try {
      const r = await fetch('/video.mjpg', { signal: abort.signal, cache: 'no-store' });
      if (!r.ok || !r.body) return;
      const reader = r.body.getReader();
      let buf = new Uint8Array(0);
      for (;;) {
        const { value, done } = await reader.read();
        if (done) return;
        buf = concat(buf, value);
        let part;
        while ((part = takePart(buf))) {
          buf = part.rest;
          if (part.jpeg) this.draw(part.jpeg);
        }
      }
    } catch {
      // Aborted or cut: the loop asks again.
    } finally {
      if (this.abort === abort) this.abort = null;
    }
  }

  async draw(jpeg) {
    let bitmap;
    try {
      bitmap = await createImageBitmap(new Blob([jpeg], { type: 'image/jpeg' }));
    } catch {
      return; // a damaged frame: the next one will do
    }
    // One more JPEG may come after WebRTC took over: it is older.
    if (!(this.webrtc && this.transport === 'webrtc')) {
      this.paint(bitmap, bitmap.width, bitmap.height);
      this.shown('mjpeg', bitmap.width, bitmap.height);
    }
    bitmap.close();
  }

  /** WebRTC's <video> is what shows the picture (laid over the canvas). */
  playsLive() {
    return this.transport === 'webrtc' && this.webrtc !== null;
  }

  /** The picture now on the canvas, for a snapshot: a WebRTC picture is
   * drawn there first. Null before the first picture. */
  still() {
    if (this.playsLive()) {
      const v = this.live;
      this.paint(v, v.videoWidth, v.videoHeight);
    }
    return this.frames > 0 && this.canvas.width > 0 ? this.canvas : null;
  }

  /** Draws one frame (`src` is `sw` × `sh`) on the canvas. */
  paint(src, sw, sh) {
    if (!sw || !sh) return;
    const quarter = this.turn % 180 !== 0;
    const w = quarter ? sh : sw;
    const h = quarter ? sw : sh;
    const c = this.canvas;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const ctx = c.getContext('2d');
    ctx.save();
    ctx.translate(w / 2, h / 2);
    ctx.rotate((this.turn * Math.PI) / 180);
    ctx.drawImage(src, -sw / 2, -sh / 2, sw, sh);
    ctx.restore();
  }

  /** A frame (`sw` × `sh`) is on screen, come over `transport`. */
  shown(transport, sw, sh) {
    if (!sw || !sh) return;
    this.lastFrameAt = performance.now();
    this.frames += 1;
    if (this.transport !== transport) {
      this.transport = transport;
      this.canvas.dataset.transport = transport;
      this.canvas.title = transport === 'webrtc' ? 'Camera (WebRTC, H.264)' : 'Camera (MJPEG)';
    }
    if (this.frames === 1) this.onState();
  }
}

function concat(a, b) {
  if (a.length === 0) return b;
  const out = new Uint8Array(a.length + b.length);
  out.set(a, 0);
  out.set(b, a.length);
  return out;
}

const CRLF2 = [13, 10, 13, 10];

function indexOf(buf, seq, from = 0) {
  outer: for (let i = from; i <= buf.length - seq.length; i++) {
    for (let j = 0; j < seq.length; j++) if (buf[i + j] !== seq[j]) continue outer;
    return i;
  }
  return -1;
}

/** One multipart part from the front of `buf`: `{ jpeg, rest }`, `{ jpeg:
 * null, rest }` when bytes were skipped to resynchronise, or null when more
 * bytes are needed. Parts carry a Content-Length (src/camera/http.rs). */
export function takePart(buf) {
  const end = indexOf(buf, CRLF2);
  if (end < 0) {
    return buf.length > MAX_HEADER ? { jpeg: null, rest: buf.subarray(buf.length - 3) } : null;
  }
  const head = new TextDecoder().decode(buf.subarray(0, end));
  const m = /content-length:\s*(\d+)/i.exec(head);
  if (!m) return { jpeg: null, rest: buf.subarray(end + 4) };
  const len = Number(m[1]);
  const start = end + 4;
  if (buf.length < start + len) return null;
  return { jpeg: buf.slice(start, start + len), rest: buf.subarray(start + len) };
}

// The camera picture: over WebRTC when the vehicle offers it (webrtc.js:
// H.264 decoded by the browser, lighter on the tether), else from the
// vehicle's MJPEG stream (/video.mjpg) read with fetch. MJPEG shows the
// first picture while WebRTC connects and stops at WebRTC's first frame; it
// takes over again by itself when WebRTC fails or stalls. Either way the page knows when each frame arrived,
// draws every frame on a canvas (rotated as the camera is mounted) and
// starts the stream again by itself when it stops or the vehicle comes
// back. The canvas is also what a snapshot saves and a recording records.
// No DOM outside the canvas it is given. docs/ARCHITECTURE.md is the map
// of the whole program.

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
  /** `canvas`: where frames are drawn; `onState()`: called when the stream
   * becomes available or unavailable (the view reads `available`). */
  constructor(canvas, onState = () => {}) {
    this.canvas = canvas;
    this.onState = onState;
    this.rotation = 0;
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

  /** Milliseconds since the latest frame (Infinity before the first). */
  frameAgeMs(now = performance.now()) {
    return this.lastFrameAt == null ? Infinity : now - this.lastFrameAt;
  }

  /** Starts reading, and keeps the stream going for the page's lifetime. */
  start() {
    if (this.running) return;
    this.running = true;
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
      iceServers: info.ice_servers || [],
      onFrame: (video, width, height) => {
        this.paint(video, width, height, 'webrtc');
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
    if (!(this.webrtc && this.transport === 'webrtc')) this.paint(bitmap, bitmap.width, bitmap.height, 'mjpeg');
    bitmap.close();
  }

  /** Draws one frame (`src` is `sw` × `sh`) that came over `transport`. */
  paint(src, sw, sh, transport) {
    if (!sw || !sh) return;
    const quarter = this.rotation % 180 !== 0;
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
    ctx.rotate((this.rotation * Math.PI) / 180);
    ctx.drawImage(src, -sw / 2, -sh / 2, sw, sh);
    ctx.restore();
    this.lastFrameAt = performance.now();
    this.frames += 1;
    if (this.transport !== transport) {
      this.transport = transport;
      c.dataset.transport = transport;
      c.title = transport === 'webrtc' ? 'Camera (WebRTC, H.264)' : 'Camera (MJPEG)';
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

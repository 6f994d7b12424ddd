// The camera picture: reads the vehicle's MJPEG stream (/video.mjpg) with
// fetch, so the page knows when each frame arrived, draws every frame on a
// canvas (rotated as the camera is mounted) and starts the stream again by
// itself when it stops or the vehicle comes back. The canvas is also what a
// snapshot saves and a recording records. No DOM outside the canvas it is
// given. docs/ARCHITECTURE.md is the map of the whole program.

/** A stream that delivers nothing for this long is started again. */
const RESTART_AFTER_MS = 3000;
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
    // A stream that stalls without closing (a network hiccup) is restarted.
    setInterval(() => {
      if (this.abort && this.frameAgeMs() > RESTART_AFTER_MS && this.streamAgeMs() > RESTART_AFTER_MS) {
        this.abort.abort();
      }
    }, 500);
  }

  /** Starts the stream again at once (the vehicle came back). */
  restart() {
    if (this.abort) this.abort.abort();
  }

  streamAgeMs() {
    return this.openedAt == null ? Infinity : performance.now() - this.openedAt;
  }

  async loop() {
    for (;;) {
      try {
        const r = await fetch('/api/video', { cache: 'no-store' });
        const available = r.ok && (await r.json()).available;
        this.setAvailable(available);
        if (available) await this.read();
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
    const quarter = this.rotation % 180 !== 0;
    const w = quarter ? bitmap.height : bitmap.width;
    const h = quarter ? bitmap.width : bitmap.height;
    const c = this.canvas;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const ctx = c.getContext('2d');
    ctx.save();
    ctx.translate(w / 2, h / 2);
    ctx.rotate((this.rotation * Math.PI) / 180);
    ctx.drawImage(bitmap, -bitmap.width / 2, -bitmap.height / 2);
    ctx.restore();
    bitmap.close();
    this.lastFrameAt = performance.now();
    this.frames += 1;
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

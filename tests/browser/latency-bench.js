// The browser half of `benches/video_latency.rs` (not a test: the bench
// runs it). Debian's Chromium against a `neptunus --sim` the bench started
// with `[camera] synthetic_timecode = true`: each frame carries its capture
// time (src/camera/timecode.rs; the decoder below must match it), and the
// page reads it back from every frame it shows.
//
//   node latency-bench.js HMI_URL VIEWER_PORT SECONDS [WARMUP_MS [FIRST_FRAME_MS]]
//
// VIEWER_PORT: where this script serves the MCM viewer page, on 127.0.0.1;
// the vehicle lists that origin in [hmi] allowed_origins, as it would
// Cockpit's. (A page Playwright fulfils itself has no address, and
// Chromium's local-network checks then block its WebSocket to loopback.)
//
// Three ways to watch, one after the other, each in a fresh browser context:
// - hmi-mjpeg: the operator page itself with WebRTC hidden from it (its
//   /api/video answer says no WebRTC), so it plays /video.mjpg as it does
//   when WebRTC fails: fetch, createImageBitmap, drawn on its canvas;
// - hmi-webrtc: the operator page as it is: WebRTC on /webrtc, each frame
//   drawn on the same canvas from requestVideoFrameCallback;
// - mcm-webrtc: tests/browser/mcm-viewer.html (mavlink-camera-manager's
//   protocol, as Cockpit speaks it) on the dedicated signalling port, a
//   <video> with requestVideoFrameCallback, served from an origin of its
//   own as Cockpit is.
// A frame's age is taken when the page has it in hand — drawn on the
// operator page's canvas, or handed to requestVideoFrameCallback — as
// Date.now() minus the code; for the WebRTC pages also at the
// callback's expectedDisplayTime and receiveTime (when its last packet
// arrived). Prints one JSON object on stdout.
import { readFileSync } from 'node:fs';
import { createServer } from 'node:http';
import { join } from 'node:path';
import { launchBrowser, until } from './harness.js';

const [hmiUrl, viewerPort, secondsArg, warmupArg, firstArg] = process.argv.slice(2);
if (!hmiUrl || !viewerPort) {
  console.error('usage: node latency-bench.js HMI_URL VIEWER_PORT SECONDS [WARMUP_MS [FIRST_FRAME_MS]]');
  process.exit(2);
}
const SECONDS = Number(secondsArg || 10);
/** Frames before this much time has passed since the first are not counted:
 * the encoder's first keyframe and the decoder's start are not the steady state. */
const WARMUP_MS = Number(warmupArg || 1000);
/** How long a way to watch may take to show its first readable frame. */
const FIRST_FRAME_MS = Number(firstArg || 30000);
const VIEWER = readFileSync(join(import.meta.dirname, 'mcm-viewer.html'));

// Runs in every page before its own scripts.
function pageProbe() {
  // The code of src/camera/timecode.rs: 2 rows × 16 blocks in the
  // bottom-left corner, 24 bits of time then CRC-8 (Dallas/Maxim) ^ 0xA5.
  const COLUMNS = 16;
  const ROWS = 2;
  const blockPx = (h) => (h >= 960 ? 32 : 16);
  const crc8 = (bytes) => {
    let crc = 0;
    for (const byte of bytes) {
      crc ^= byte;
      for (let i = 0; i < 8; i++) crc = crc & 1 ? (crc >> 1) ^ 0x8c : crc >> 1;
    }
    return crc;
  };
  /** `rgba`: the code's region (16 × 2 blocks of `b` pixels). */
  const decode = (rgba, b) => {
    const stride = COLUMNS * b;
    const m0 = b >> 2;
    const m1 = b - (b >> 2);
    let code = 0;
    for (let i = 0; i < COLUMNS * ROWS; i++) {
      const bx = (i % COLUMNS) * b;
      const by = Math.floor(i / COLUMNS) * b;
      let sum = 0;
      for (let y = by + m0; y < by + m1; y++) {
        for (let x = bx + m0; x < bx + m1; x++) {
          const p = (y * stride + x) * 4;
          sum += (rgba[p] * 77 + rgba[p + 1] * 150 + rgba[p + 2] * 29) >> 8;
        }
      }
      const mean = sum / ((m1 - m0) * (m1 - m0));
      let bit;
      if (mean <= 80) bit = 0;
      else if (mean >= 175) bit = 1;
      else return null;
      code = code * 2 + bit;
    }
    const t = Math.floor(code / 256);
    const check = code % 256;
    return (crc8([(t >> 16) & 0xff, (t >> 8) & 0xff, t & 0xff]) ^ 0xa5) === check ? t : null;
  };
  const M = 1 << 24;
  const age = (code, nowMs) => {
    const d = (((Math.floor(nowMs) % M) - code) % M + M) % M;
    return d >= M / 2 ? d - M : d;
  };
  // performance.now() → the Unix clock, taken afresh each time (the two
  // clocks may drift apart over a long page life).
  const toUnix = (perfMs) => perfMs + (Date.now() - performance.now());

  // `expect`: the operator page's transport being measured; frames of the
  // other (MJPEG while WebRTC connects) are not counted.
  const rec = window.__latency = {
    on: false, expect: null, samples: [], rejected: 0, repeated: 0, first: null, last: null,
  };
  const record = (rgba, b, meta, transport) => {
    if (rec.expect && transport !== rec.expect) return;
    const now = Date.now();
    const code = decode(rgba, b);
    if (code === null) { if (rec.on) rec.rejected += 1; return; }
    if (code === rec.last) { if (rec.on) rec.repeated += 1; return; }
    rec.last = code;
    if (rec.first === null) rec.first = now;
    if (!rec.on) return;
    rec.samples.push([
      age(code, now),
      meta && meta.expectedDisplayTime ? age(code, toUnix(meta.expectedDisplayTime)) : null,
      meta && meta.receiveTime ? age(code, toUnix(meta.receiveTime)) : null,
    ]);
  };

  // The requestVideoFrameCallback metadata of the frame being handled, for
  // the operator page (its callback draws the frame on its canvas).
  let meta = null;
  const rvfc = HTMLVideoElement.prototype.requestVideoFrameCallback;
  HTMLVideoElement.prototype.requestVideoFrameCallback = function (cb) {
    return rvfc.call(this, (now, m) => {
      meta = m;
      try { cb(now, m); } finally { meta = null; }
    });
  };
  // The operator page: read the code back from its video canvas right
  // after each frame is drawn on it.
  const draw = CanvasRenderingContext2D.prototype.drawImage;
  CanvasRenderingContext2D.prototype.drawImage = function (src, ...rest) {
    draw.call(this, src, ...rest);
    const c = this.canvas;
    if (!(c instanceof HTMLCanvasElement) || c.id !== 'video') return;
    const b = blockPx(c.height);
    if (c.width < COLUMNS * b || c.height < ROWS * b) return;
    const video = src instanceof HTMLVideoElement;
    const img = this.getImageData(0, c.height - ROWS * b, COLUMNS * b, ROWS * b);
    record(img.data, b, video ? meta : null, video ? 'webrtc' : 'mjpeg');
  };
  // The MCM viewer: its <video id="v">, every frame it presents.
  addEventListener('DOMContentLoaded', () => {
    const v = document.getElementById('v');
    if (!(v instanceof HTMLVideoElement)) return;
    const scratch = document.createElement('canvas');
    const ctx = scratch.getContext('2d', { willReadFrequently: true });
    const onFrame = (_now, m) => {
      const h = m.height;
      const b = blockPx(h);
      if (m.width >= COLUMNS * b && h >= ROWS * b) {
        scratch.width = COLUMNS * b;
        scratch.height = ROWS * b;
        draw.call(ctx, v, 0, h - ROWS * b, COLUMNS * b, ROWS * b, 0, 0, COLUMNS * b, ROWS * b);
        record(ctx.getImageData(0, 0, COLUMNS * b, ROWS * b).data, b, m, 'webrtc');
      }
      rvfc.call(v, onFrame);
    };
    rvfc.call(v, onFrame);
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Opens `url` in a fresh context (`setup(context)` first), waits for a
 * first decoded code over `transport`, lets it settle, and collects for
 * SECONDS. */
async function measure(browser, name, url, transport, setup = async () => {}) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 } });
  const problems = [];
  let page = null;
  try {
    await context.addInitScript(pageProbe);
    await context.addInitScript((t) => { window.__latency.expect = t; }, transport);
    await setup(context);
    page = await context.newPage();
    page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
    const opened = Date.now();
    await page.goto(url);
    const first = await until(() => page.evaluate(() => window.__latency.first), FIRST_FRAME_MS, `a first readable frame (${name})`);
    await sleep(Math.max(0, first + WARMUP_MS - Date.now()));
    await page.evaluate(() => { window.__latency.on = true; });
    const t0 = Date.now();
    await sleep(SECONDS * 1000);
    const r = await page.evaluate(() => { window.__latency.on = false; return window.__latency; });
    return {
      samples: r.samples,
      rejected: r.rejected,
      repeated: r.repeated,
      seconds: (Date.now() - t0) / 1000,
      first_frame_ms: first - opened,
      problems,
    };
  } catch (e) {
    // What the MCM viewer saw of its session, if it is that page.
    const viewer = await page?.evaluate(() => window.viewer && {
      state: window.viewer.state, frames: window.viewer.frames, log: window.viewer.log, errors: window.viewer.errors,
    }).catch(() => null);
    return { error: `${e.message || e}${viewer ? ` — viewer: ${JSON.stringify(viewer)}` : ''}`, problems };
  } finally {
    await context.close();
  }
}

const browser = await launchBrowser();
const out = { chromium: browser.version(), seconds: SECONDS, paths: {} };
try {
  const info = await (await fetch(new URL('api/webrtc', hmiUrl))).json();
  out.paths['hmi-mjpeg'] = await measure(browser, 'operator page, MJPEG', hmiUrl, 'mjpeg', async (context) => {
    // The page asks /api/video whether WebRTC runs: it is told no.
    await context.route('**/api/video', async (route) => {
      const r = await route.fetch();
      const body = await r.json();
      await route.fulfill({ response: r, json: { ...body, webrtc: null } });
    });
  });
  out.paths['hmi-webrtc'] = await measure(browser, 'operator page, WebRTC', hmiUrl, 'webrtc');
  const server = createServer((_req, res) => {
    res.writeHead(200, { 'content-type': 'text/html' });
    res.end(VIEWER);
  });
  await new Promise((ok, fail) => server.once('error', fail).listen(Number(viewerPort), '127.0.0.1', ok));
  try {
    const ws = `ws://${new URL(hmiUrl).hostname}:${info.signalling_port}/`;
    out.paths['mcm-webrtc'] = await measure(browser, 'MCM-protocol viewer',
      `http://127.0.0.1:${viewerPort}/?ws=${encodeURIComponent(ws)}`, 'webrtc');
  } finally {
    server.close();
  }
} finally {
  await browser.close();
}
process.stdout.write(`${JSON.stringify(out)}\n`);

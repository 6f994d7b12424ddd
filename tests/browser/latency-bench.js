// The browser half of `benches/video_latency.rs` (not a test: the bench
// runs it). Debian's Chromium against a `neptunus --sim` the bench started
// with `[camera] synthetic_timecode = true`: each frame carries its capture
// time (src/camera/timecode.rs; the decoder below must match it), and the
// page reads it back from every frame it shows.
//
//   node latency-bench.js HMI_URL VIEWER_PORT SECONDS [WARMUP_MS [FIRST_FRAME_MS]]
//
// LATENCY_VEHICLE_TOML: the config file of the vehicle this script starts
// for Cockpit itself (NEPTUNUS_BIN), on port 80 of a loopback address of
// its own, as cockpit-harness.js does for cockpit.test.js.
//
// VIEWER_PORT: where this script serves the MCM viewer page, on 127.0.0.1;
// the vehicle lists that origin in [hmi] allowed_origins, as it would
// Cockpit's. (A page Playwright fulfils itself has no address, and
// Chromium's local-network checks then block its WebSocket to loopback.)
//
// Four ways to watch, one after the other, each in a fresh browser context:
// - hmi-mjpeg: the operator page itself with WebRTC hidden from it (its
//   /api/video answer says no WebRTC), so it plays /video.mjpg as it does
//   when WebRTC fails: fetch, createImageBitmap, drawn on its canvas;
// - hmi-webrtc: the operator page as it is: WebRTC on /webrtc, shown by
//   its own <video> over the canvas, read from that <video> in
//   requestVideoFrameCallback;
// - mcm-webrtc: tests/browser/mcm-viewer.html (mavlink-camera-manager's
//   protocol, as Cockpit speaks it) on the dedicated signalling port, a
//   <video> with requestVideoFrameCallback, served from an origin of its
//   own as Cockpit is;
// - cockpit-webrtc: the real Cockpit (cockpit-harness.js), given only the
//   vehicle's address, playing the vehicle's WebRTC in its own player; its
//   code untouched, read from the <video> elements it plays a stream in
//   (found when it sets their srcObject), in requestVideoFrameCallback.
//   Skipped, with the reason, where Cockpit's build is missing or port 80
//   cannot be had.
// A frame's age is taken when the page has it in hand — drawn on the
// operator page's canvas (MJPEG), or handed to requestVideoFrameCallback — as
// Date.now() minus the code; for the WebRTC pages also at the
// callback's expectedDisplayTime and receiveTime (when its last packet
// arrived). For the WebRTC ways also the time from asking (the page's
// startSession on the signalling WebSocket) to the first picture read.
// Prints one JSON object on stdout.
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { launchBrowser, until } from './harness.js';
import { cockpitContext, cockpitMissing, cockpitVehicle, launchCockpitBrowser, serveCockpit } from './cockpit-harness.js';

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
  // `watchVideos`: read every <video> the page gives a stream (Cockpit's).
  const rec = window.__latency = {
    on: false, expect: null, watchVideos: false, samples: [], rejected: 0, repeated: 0, first: null, last: null,
    drawMs: [], animationFrameMs: [], videos: [],
  };
  // Frames the page's <video>s (those given a stream) decoded and dropped.
  rec.quality = () => rec.videos.reduce((q, v) => {
    const p = v.getVideoPlaybackQuality();
    return [q[0] + p.totalVideoFrames, q[1] + p.droppedVideoFrames, q[2] + 1];
  }, [0, 0, 0]);
  // The page's own cost per frame, measured: each drawImage of a picture on
  // the operator page's video canvas, and each animation-frame callback
  // (the HUD, the gamepad, the view).
  const raf = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (cb) => raf((t) => {
    const t0 = performance.now();
    try { cb(t); } finally { if (rec.on) rec.animationFrameMs.push(performance.now() - t0); }
  });
  const seen = new Set();
  const record = (rgba, b, meta, transport) => {
    if (rec.expect && transport !== rec.expect) return;
    const now = Date.now();
    const code = decode(rgba, b);
    if (code === null) { if (rec.on) rec.rejected += 1; return; }
    // A frame counts where it is shown first: the same frame again (shown
    // twice, or by a second <video> of the page, as Cockpit has) is not.
    if (code === rec.last || seen.has(code)) { if (rec.on) rec.repeated += 1; return; }
    rec.last = code;
    seen.add(code);
    if (seen.size > 600) seen.delete(seen.values().next().value);
    if (rec.first === null) rec.first = now;
    if (!rec.on) return;
    rec.samples.push([
      age(code, now),
      meta && meta.expectedDisplayTime ? age(code, toUnix(meta.expectedDisplayTime)) : null,
      meta && meta.receiveTime ? age(code, toUnix(meta.receiveTime)) : null,
    ]);
  };

  // The requestVideoFrameCallback metadata of the frame being handled, for
  // a WebRTC picture the operator page draws on its canvas (a snapshot or
  // a recording).
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
    const t0 = performance.now();
    draw.call(this, src, ...rest);
    const c = this.canvas;
    if (!(c instanceof HTMLCanvasElement) || c.id !== 'video') return;
    if (rec.on) rec.drawMs.push(performance.now() - t0);
    const b = blockPx(c.height);
    if (c.width < COLUMNS * b || c.height < ROWS * b) return;
    const video = src instanceof HTMLVideoElement;
    const img = this.getImageData(0, c.height - ROWS * b, COLUMNS * b, ROWS * b);
    record(img.data, b, video ? meta : null, video ? 'webrtc' : 'mjpeg');
  };
  // A <video>: every frame it presents.
  const watched = new WeakSet();
  const watchVideo = (v) => {
    if (watched.has(v)) return;
    watched.add(v);
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
  };
  // The MCM viewer: its <video id="v">.
  addEventListener('DOMContentLoaded', () => {
    const v = document.getElementById('v');
    if (v instanceof HTMLVideoElement) watchVideo(v);
  });
  // Cockpit: each <video> it hands a stream.
  const srcObject = Object.getOwnPropertyDescriptor(HTMLMediaElement.prototype, 'srcObject');
  Object.defineProperty(HTMLMediaElement.prototype, 'srcObject', {
    ...srcObject,
    set(stream) {
      srcObject.set.call(this, stream);
      if (stream && this instanceof HTMLVideoElement && !rec.videos.includes(this)) rec.videos.push(this);
      if (rec.watchVideos && stream && this instanceof HTMLVideoElement) watchVideo(this);
    },
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** [p50, p95, count] of `ms`, or null when empty. */
function spread(ms) {
  if (!ms.length) return null;
  const s = [...ms].sort((a, b) => a - b);
  const at = (q) => s[Math.round((s.length - 1) * q)];
  return [at(0.5), at(0.95), s.length];
}

/** Cockpit, given only the address of a vehicle of its own, in a browser
 * of its own. Its app takes seconds to load on a busy machine: its first
 * picture is waited for longer. */
async function measureCockpit() {
  const missing = cockpitMissing();
  if (missing) return { error: `skipped: ${missing}`, problems: [] };
  const toml = process.env.LATENCY_VEHICLE_TOML;
  if (!toml) return { error: 'no LATENCY_VEHICLE_TOML (the bench sets it)', problems: [] };
  const server = await serveCockpit();
  const data = mkdtempSync(join(tmpdir(), 'neptunus-latency-cockpit-'));
  let v = null;
  let browser = null;
  try {
    v = await cockpitVehicle(data, { origin: server.origin, toml });
    browser = await launchCockpitBrowser();
    const r = await measure(browser, 'Cockpit', `${server.origin}/`, 'webrtc', {
      newContext: () => cockpitContext(browser, v.ip, { width: 1280, height: 800 }),
      watchVideos: true,
      firstFrameMs: 4 * FIRST_FRAME_MS,
    });
    if (r.error) r.error += `\n--- neptunus (Cockpit's) stderr (tail) ---\n${v.stderr().slice(-1500)}`;
    return r;
  } catch (e) {
    return { error: `${e.message || e}`, problems: [] };
  } finally {
    await browser?.close();
    await v?.stop();
    server.close();
    rmSync(data, { recursive: true, force: true });
  }
}

/** Opens `url` in a fresh context (`setup(context)` first; `newContext`
 * makes it), waits for a first decoded code over `transport`, lets it
 * settle, and collects for SECONDS. */
async function measure(browser, name, url, transport, {
  setup = async () => {},
  newContext = () => browser.newContext({ viewport: { width: 1280, height: 800 } }),
  watchVideos = false,
  firstFrameMs = FIRST_FRAME_MS,
} = {}) {
  const context = await newContext();
  const problems = [];
  let page = null;
  try {
    await context.addInitScript(pageProbe);
    await context.addInitScript(([t, all]) => {
      window.__latency.expect = t;
      window.__latency.watchVideos = all;
    }, [transport, watchVideos]);
    await setup(context);
    page = await context.newPage();
    page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
    // Asking for the picture: the page's first startSession.
    let asked = null;
    page.on('websocket', (ws) => ws.on('framesent', (f) => {
      if (asked === null && typeof f.payload === 'string' && f.payload.includes('"startSession"')) asked = Date.now();
    }));
    const opened = Date.now();
    await page.goto(url);
    const first = await until(() => page.evaluate(() => window.__latency.first), firstFrameMs, `a first readable frame (${name})`);
    await sleep(Math.max(0, first + WARMUP_MS - Date.now()));
    const q0 = await page.evaluate(() => { window.__latency.on = true; return window.__latency.quality(); });
    const t0 = Date.now();
    await sleep(SECONDS * 1000);
    const r = await page.evaluate(() => {
      window.__latency.on = false;
      const { samples, rejected, repeated, drawMs, animationFrameMs } = window.__latency;
      return { samples, rejected, repeated, drawMs, animationFrameMs, q: window.__latency.quality() };
    });
    return {
      samples: r.samples,
      rejected: r.rejected,
      repeated: r.repeated,
      seconds: (Date.now() - t0) / 1000,
      first_frame_ms: first - opened,
      asked_ms: asked === null ? null : first - asked,
      // Over the window: [decoded, dropped, <video>s].
      video_frames: r.q[2] ? [r.q[0] - q0[0], r.q[1] - q0[1], r.q[2]] : null,
      draw_ms: spread(r.drawMs),
      animation_frame_ms: spread(r.animationFrameMs),
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
  out.paths['hmi-mjpeg'] = await measure(browser, 'operator page, MJPEG', hmiUrl, 'mjpeg', {
    setup: async (context) => {
      // The page asks /api/video whether WebRTC runs: it is told no.
      await context.route('**/api/video', async (route) => {
        const r = await route.fetch();
        const body = await r.json();
        await route.fulfill({ response: r, json: { ...body, webrtc: null } });
      });
    },
  });
  out.paths['hmi-webrtc'] = await measure(browser, 'operator page, WebRTC', hmiUrl, 'webrtc', { watchVideos: true });
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
out.paths['cockpit-webrtc'] = await measureCockpit();
process.stdout.write(`${JSON.stringify(out)}\n`);

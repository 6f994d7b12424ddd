// WebRTC video from the user's side: Debian's Chromium, on a page of its
// own origin that speaks mavlink-camera-manager's signalling protocol the
// way Cockpit does (mcm-viewer.html), against `neptunus --sim`. The page is
// served from another origin than the HMI, as Cockpit is, and that origin is
// listed in [hmi] allowed_origins. Waits poll a condition with a deadline.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { spawnSync } from 'node:child_process';
import { tmpdir } from 'node:os';
import { createServer, request } from 'node:http';
import { createSocket } from 'node:dgram';
import { join } from 'node:path';
import { launchBrowser, openPage, startVehicle, until } from './harness.js';

const VIEWER = readFileSync(join(import.meta.dirname, 'mcm-viewer.html'));
const FPS = 30;

let browser;
let server;
let origin;
before(async () => {
  browser = await launchBrowser();
  server = createServer((_req, res) => {
    res.writeHead(200, { 'content-type': 'text/html' });
    res.end(VIEWER);
  });
  await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
  origin = `http://127.0.0.1:${server.address().port}`;
});
after(async () => {
  await browser?.close();
  server?.close();
});

/** The vehicle with the synthetic camera at 30 fps, no RTP to ground
 * stations, the signalling's own port on a free loopback port, and the
 * viewer page's origin allowed. */
async function vehicle(extra = []) {
  return startVehicle(['--video-rtp', 'off', '--webrtc-signalling', '127.0.0.1:0', ...extra], {
    toml: `[camera]\nsource = "synthetic"\nfps = ${FPS}\n`,
    hmiToml: `allowed_origins = ["${origin}"]`,
  });
}

async function withVehicle(body, extra) {
  const v = await vehicle(extra);
  try {
    await body(v);
  } catch (e) {
    e.message += `\n--- neptunus stderr (tail) ---\n${v.stderr().slice(-3000)}`;
    throw e;
  } finally {
    await v.stop();
  }
}

const json = async (url) => (await fetch(url)).json();

/** A viewer page on `ws`; returns the page. */
async function openViewer(ws) {
  const context = await browser.newContext();
  const page = await context.newPage();
  await page.goto(`${origin}/?ws=${encodeURIComponent(ws)}`);
  return page;
}

const viewerState = (page) => page.evaluate(() => ({ ...window.viewer, offer: undefined }));

/** The processes whose parent is `pid` and whose name is `name` (any
 * name when `name` is null). */
function children(pid, name) {
  const out = [];
  for (const d of readdirSync('/proc')) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const stat = readFileSync(`/proc/${d}/stat`, 'utf8');
      const comm = stat.slice(stat.indexOf('(') + 1, stat.lastIndexOf(')'));
      const ppid = Number(stat.slice(stat.lastIndexOf(')') + 2).split(' ')[1]);
      if (ppid === pid && (name === null || comm === name)) out.push(Number(d));
    } catch { /* the process ended meanwhile */ }
  }
  return out;
}

test('a viewer speaking mavlink-camera-manager\'s protocol on its own port decodes the camera\'s H.264, with --video-rtp off', () => withVehicle(async (v) => {
  const info = await json(`${v.url}api/webrtc`);
  assert.ok(info.signalling_port > 0, JSON.stringify(info));
  assert.equal(info.streams.length, 1);
  const stream = info.streams[0];
  assert.deepEqual([stream.encode, stream.width, stream.height, stream.interval], ['H264', 640, 480, `1/${FPS}`]);
  const page = await openViewer(`ws://127.0.0.1:${info.signalling_port}/`);
  const first = await until(async () => {
    const s = await viewerState(page);
    return s.frames > 0 && s;
  }, 20000, 'a first decoded frame');
  const offer = await page.evaluate(() => window.viewer.offer);
  assert.match(offer, /profile-level-id=42e01f/);
  assert.match(offer, /packetization-mode=1/);
  console.log(`time to first frame: ${first.firstFrameMs} ms from opening the page (${first.log.join(', ')})`);
  // Ten seconds of decoding against the camera's own frames in the same window.
  const cam0 = (await json(`${v.url}camera/status`)).frames_total;
  const dec0 = (await viewerState(page)).frames;
  const t0 = Date.now();
  await until(() => Date.now() - t0 >= 10000, 12000, 'ten seconds');
  const cam1 = (await json(`${v.url}camera/status`)).frames_total;
  const s = await viewerState(page);
  const decoded = s.frames - dec0;
  const made = cam1 - cam0;
  console.log(`10 s: the camera made ${made} frames, Chromium decoded ${decoded} (${(100 * decoded / made).toFixed(0)} %)`);
  assert.ok(decoded >= 0.8 * made, `decoded ${decoded} of ${made} frames`);
  // A debug build on a busy machine draws fewer than 30 a second; the
  // camera must still be running.
  assert.ok(made >= 30, `the camera made only ${made} frames in 10 s`);
  assert.equal(s.width, 640);
  assert.equal(s.height, 480);
  assert.equal(await page.evaluate(() => document.getElementById('v').videoWidth), 640);
  assert.deepEqual(s.errors, []);
  assert.equal(s.ended, null);
}));

test('two viewers, one on the HMI\'s /webrtc, cost one encode; the encoder stops when they leave', () => withVehicle(async (v) => {
  const info = await json(`${v.url}api/webrtc`);
  const hmi = new URL(v.url);
  const a = await openViewer(`ws://127.0.0.1:${info.signalling_port}/`);
  const b = await openViewer(`ws://${hmi.host}${info.path}`);
  for (const [name, page] of [['the viewer on the own port', a], ['the viewer on /webrtc', b]]) {
    await until(async () => (await viewerState(page)).frames > 2 * FPS, 30000, `two seconds of frames in ${name}`);
  }
  const encoders = children(v.pid, 'ffmpeg');
  assert.equal(encoders.length, 1, `ffmpeg children of neptunus: ${encoders}`);
  // Both keep decoding from the one encode.
  const before = [(await viewerState(a)).frames, (await viewerState(b)).frames];
  await until(async () => (await viewerState(a)).frames > before[0] + FPS && (await viewerState(b)).frames > before[1] + FPS,
    10000, 'a second more of frames in both');
  assert.equal(children(v.pid, 'ffmpeg').length, 1);
  await a.context().close();
  await b.context().close();
  await until(() => children(v.pid, 'ffmpeg').length === 0, 15000, 'the encoder to stop after the last viewer left');
  await until(async () => (await json(`${v.url}camera/status`)).state === 'idle', 15000, 'the camera to go idle');
}));

test('a viewer beyond camera.webrtc.max_viewers is told why its session ended', async () => {
  const v = await startVehicle(['--video-rtp', 'off', '--webrtc-signalling', '127.0.0.1:0'], {
    toml: `[camera]\nsource = "synthetic"\nfps = ${FPS}\n[camera.webrtc]\nmax_viewers = 1\n`,
    hmiToml: `allowed_origins = ["${origin}"]`,
  });
  try {
    const info = await json(`${v.url}api/webrtc`);
    const ws = `ws://127.0.0.1:${info.signalling_port}/`;
    const a = await openViewer(ws);
    await until(async () => (await viewerState(a)).frames > 0, 20000, 'the first viewer\'s picture');
    const b = await openViewer(ws);
    const ended = await until(async () => (await viewerState(b)).ended, 10000, 'the second viewer\'s session ended');
    assert.match(ended, /at most 1 WebRTC viewers at once \(camera.webrtc.max_viewers\)/);
    assert.equal((await viewerState(b)).frames, 0);
    // The first one goes on.
    const n = (await viewerState(a)).frames;
    await until(async () => (await viewerState(a)).frames > n + 5, 10000, 'the first viewer still decoding');
  } catch (e) {
    e.message += `\n--- neptunus stderr (tail) ---\n${v.stderr().slice(-3000)}`;
    throw e;
  } finally {
    await v.stop();
  }
});

/** A STUN server on loopback that tells every asker it is 203.0.113.7
 * (a documentation address) on the port it asked from. */
async function stunServer() {
  const sock = createSocket('udp4');
  sock.on('message', (m, from) => {
    if (m.length < 20 || m.readUInt16BE(0) !== 0x0001) return;
    const res = Buffer.alloc(32);
    res.writeUInt16BE(0x0101, 0);
    res.writeUInt16BE(12, 2);
    m.copy(res, 4, 4, 20); // magic cookie and transaction id
    res.writeUInt16BE(0x0020, 20); // XOR-MAPPED-ADDRESS
    res.writeUInt16BE(8, 22);
    res.writeUInt16BE(0x0001, 24);
    res.writeUInt16BE(from.port ^ 0x2112, 26);
    res.writeUInt32BE((((203 << 24) | (0 << 16) | (113 << 8) | 7) ^ 0x2112a442) >>> 0, 28);
    sock.send(res, from.port, from.address);
  });
  await new Promise((ok) => sock.bind(0, '127.0.0.1', ok));
  return sock;
}

test('with a STUN server configured, the offer carries the public address it told', async () => {
  const stun = await stunServer();
  const v = await vehicle(['--ice-server', `stun:127.0.0.1:${stun.address().port}`]);
  try {
    await until(() => /public address from STUN/.test(v.stderr()), 15000, 'the STUN answer in the log');
    const info = await json(`${v.url}api/webrtc`);
    assert.deepEqual(info.ice_servers, [{ urls: `stun:127.0.0.1:${stun.address().port}` }]);
    const page = await openViewer(`ws://127.0.0.1:${info.signalling_port}/`);
    await until(async () => (await viewerState(page)).frames > 0, 20000, 'a picture (over a host candidate)');
    const offer = await page.evaluate(() => window.viewer.offer);
    assert.match(offer, /a=candidate:\S+ 1 udp \d+ 203\.0\.113\.7 \d+ typ srflx raddr/);
  } catch (e) {
    e.message += `\n--- neptunus stderr (tail) ---\n${v.stderr().slice(-3000)}`;
    throw e;
  } finally {
    await v.stop();
    stun.close();
  }
});

test('the signalling refuses a foreign page and answers bad messages with the reason', () => withVehicle(async (v) => {
  const info = await json(`${v.url}api/webrtc`);
  // A WebSocket upgrade from a page whose origin is not allowed: 403; from
  // the HMI's own page (its origin is on the HMI's port): admitted.
  const upgrade = (origin) => new Promise((ok, fail) => {
    const req = request({
      host: '127.0.0.1', port: info.signalling_port, path: '/',
      headers: {
        Connection: 'Upgrade', Upgrade: 'websocket', Origin: origin,
        'Sec-WebSocket-Version': '13', 'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==',
      },
    });
    req.on('response', (res) => { res.resume(); ok(res.statusCode); });
    req.on('upgrade', (_res, socket) => { socket.destroy(); ok(101); });
    req.on('error', fail);
    req.end();
  });
  assert.equal(await upgrade('http://evil.example.com'), 403);
  assert.equal(await upgrade(new URL(v.url).origin), 101);
  // From the allowed origin: garbage is answered with an error, and the
  // connection still works afterwards.
  const page = await openViewer(`ws://127.0.0.1:${info.signalling_port}/`);
  const replies = await page.evaluate((url) => new Promise((ok) => {
    const ws = new WebSocket(url);
    const got = [];
    ws.onmessage = (e) => {
      got.push(JSON.parse(e.data));
      if (got.length === 4) ok(got);
    };
    ws.onopen = () => {
      ws.send('not json');
      ws.send(JSON.stringify({ type: 'question', content: { type: 'startSession', content: { consumer_id: 'x', producer_id: 'no-such-stream' } } }));
      ws.send(JSON.stringify({ type: 'negotiation', content: { type: 'iceNegotiation', content: { consumer_id: 'x', producer_id: 'y', session_id: 'z', ice: { candidate: 'candidate:1 1 udp 1 1.2.3.4 5 typ host' } } } }));
      ws.send(JSON.stringify({ type: 'question', content: { type: 'peerId' } }));
    };
  }), `ws://127.0.0.1:${info.signalling_port}/`);
  assert.equal(replies[0].type, 'error');
  assert.match(replies[0].content, /not a signalling message/);
  assert.match(replies[1].content, /no stream with id "no-such-stream"/);
  assert.match(replies[2].content, /no session "z" of this connection/);
  assert.equal(replies[3].type, 'answer');
  assert.equal(replies[3].content.type, 'peerId');
  await until(() => /WebRTC signalling: a message from .* refused/.test(v.stderr()), 5000, 'the refusal in the log');
}));

test('the HMI page plays WebRTC; when the picture stops it shows VIDEO LOST, then goes on over MJPEG', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  const video = () => page.evaluate(() => ({
    transport: window.neptunus.video.transport, frames: window.neptunus.video.frames,
    lost: !document.getElementById('video-lost').hidden,
  }));
  await until(async () => { const s = await video(); return s.transport === 'webrtc' && s.frames > 20; }, 20000, 'frames over WebRTC');
  // The picture is shown as soon as it is decoded: the page asks its
  // receiver for no jitter buffer, and Chromium took the vehicle's
  // playout-delay extension into its answer.
  const rx = await page.evaluate(() => {
    const { pc, video } = window.neptunus.video.webrtc;
    const [track] = video.srcObject.getVideoTracks();
    const r = pc.getReceivers().find((x) => x.track === track);
    return { target: r.jitterBufferTarget, answer: pc.localDescription.sdp };
  });
  assert.equal(rx.target, 0, 'jitterBufferTarget');
  assert.match(rx.answer, /a=extmap:\d+ http:\/\/www\.webrtc\.org\/experiments\/rtp-hdrext\/playout-delay/);
  // The picture is the session's own <video>, shown over the canvas as the
  // browser composites it: the page draws no WebRTC frame on its canvas.
  const shown = await page.evaluate(() => {
    const live = document.getElementById('video-live');
    const draw = CanvasRenderingContext2D.prototype.drawImage;
    window.__draws = 0;
    CanvasRenderingContext2D.prototype.drawImage = function (...a) {
      if (this.canvas.id === 'video') window.__draws += 1;
      return draw.apply(this, a);
    };
    return { mine: window.neptunus.video.webrtc.video === live, width: live.videoWidth };
  });
  assert.deepEqual(shown, { mine: true, width: 640 });
  assert.ok(await page.isVisible('[data-testid=video-live]'), 'the WebRTC picture is shown');
  const f0 = (await video()).frames;
  await until(async () => (await video()).frames > f0 + 10, 10000, 'ten more WebRTC frames');
  assert.equal(await page.evaluate(() => window.__draws), 0, 'WebRTC frames drawn on the canvas');
  // A snapshot is the WebRTC picture, drawn on the canvas for it.
  const [d] = await Promise.all([page.waitForEvent('download', { timeout: 15000 }), page.click('[data-testid=snapshot]')]);
  const jpeg = readFileSync(await d.path());
  assert.equal(jpeg.subarray(0, 3).toString('hex'), 'ffd8ff', 'a JPEG');
  assert.ok(jpeg.length > 2000, `${jpeg.length} bytes`);
  assert.deepEqual(await page.evaluate(() => [document.getElementById('video').width, window.__draws]), [640, 1]);
  // A camera mounted a quarter turn: the turned picture fills the box as
  // the canvas's would, not overflowing it.
  const box = await page.locator('[data-testid=video-box]').boundingBox();
  await page.evaluate(() => { window.neptunus.video.rotation = 90; });
  const turned = await page.locator('[data-testid=video-live]').boundingBox();
  for (const k of ['x', 'y', 'width', 'height']) assert.ok(Math.abs(turned[k] - box[k]) <= 1, `turned ${k}: ${turned[k]} in a box of ${box[k]}`);
  await page.evaluate(() => { window.neptunus.video.rotation = 0; });
  // Nobody reads /video.mjpg any more: the page's picture is the WebRTC one.
  await until(async () => (await json(`${v.url}camera/status`)).viewers === 0, 5000, 'the MJPEG stream closed');
  // The encoder stops giving pictures: the page says so, then gives WebRTC
  // up and reads MJPEG, and the picture is back.
  const [encoder] = children(v.pid, 'ffmpeg');
  assert.ok(encoder, 'the encoder runs');
  process.kill(encoder, 'SIGSTOP');
  try {
    await until(async () => (await video()).lost, 10000, 'VIDEO LOST while the WebRTC picture is frozen');
    await until(async () => (await video()).transport === 'mjpeg', 15000, 'the page to fall back to MJPEG');
    await until(async () => !(await video()).lost, 10000, 'the picture back over MJPEG');
    assert.ok(await page.isHidden('[data-testid=video-live]'), 'the WebRTC <video> gone with its session');
  } finally {
    // Gone already, once the WebRTC session ended and nobody else wanted it.
    try { process.kill(encoder, 'SIGCONT'); } catch { /* ended */ }
  }
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the HMI page falls back to MJPEG by itself when the network blocks WebRTC', () => withVehicle(async (v) => {
  // A network where the vehicle's addresses cannot be reached over UDP: the
  // page never learns one (every candidate is taken out of the signalling),
  // so ICE can only fail.
  const context = await browser.newContext();
  await context.routeWebSocket(/\/webrtc$/, (ws) => {
    const server = ws.connectToServer();
    ws.onMessage((m) => server.send(m));
    server.onMessage((m) => {
      const msg = JSON.parse(m);
      const c = msg.content || {};
      if (c.type === 'iceNegotiation') return;
      if (c.type === 'mediaNegotiation') {
        c.content.sdp.sdp = c.content.sdp.sdp.split('\r\n').filter((l) => !l.startsWith('a=candidate')).join('\r\n');
      }
      ws.send(JSON.stringify(msg));
    });
  });
  const page = await context.newPage();
  const problems = [];
  page.on('console', (m) => { if (m.type() === 'error') problems.push(m.text()); });
  await page.goto(v.url);
  const t0 = Date.now();
  // MJPEG shows the picture while WebRTC tries, and goes on once it gave up.
  await until(() => page.evaluate(() => window.neptunus.video.transport === 'mjpeg' && window.neptunus.video.frames > 0),
    10000, 'a picture over MJPEG');
  const first = Date.now() - t0;
  const why = await until(() => page.evaluate(() => window.neptunus.video.webrtcFailed), 15000, 'WebRTC given up');
  const frames = await page.evaluate(() => window.neptunus.video.frames);
  await until(() => page.evaluate((n) => window.neptunus.video.transport === 'mjpeg' && window.neptunus.video.frames > n + 5, frames),
    10000, 'frames over MJPEG after WebRTC was given up');
  console.log(`first MJPEG picture ${first} ms after opening the page; WebRTC given up after ${Date.now() - t0} ms: ${why}`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('with --webrtc off the page plays MJPEG at once and nothing listens for signalling', () => withVehicle(async (v) => {
  const info = await json(`${v.url}api/video`);
  assert.equal(info.webrtc, null);
  const { page, context, problems } = await openPage(browser, v.url);
  await until(() => page.evaluate(() => window.neptunus.video.transport === 'mjpeg' && window.neptunus.video.frames > 3), 15000, 'frames over MJPEG');
  assert.equal(await page.evaluate(() => window.neptunus.video.webrtcFailed), null, 'WebRTC was never tried');
  assert.doesNotMatch(v.stderr(), /WebRTC signalling \(mavlink-camera-manager/);
  assert.deepEqual(problems, []);
  await context.close();
}, ['--webrtc', 'off']));

/** A camera that encodes H.264 itself, read through V4L2: a recording of
 * what one gives (an Annex B stream of access units: libx264 from testsrc,
 * 640×480 at 30 fps, constrained baseline, the SPS/PPS only at its start,
 * a keyframe every second) in a file in the device's place, which the
 * vehicle plays at 30 fps through the same path as a device's buffers. */
test('a camera\'s own H.264 plays in a viewer and in the page, with no process on the vehicle encoding it', async () => {
  const dir = mkdtempSync(join(tmpdir(), 'neptunus-h264-camera-'));
  const clip = join(dir, 'camera.h264');
  const made = spawnSync('ffmpeg', ['-hide_banner', '-loglevel', 'error', '-f', 'lavfi', '-i', `testsrc2=size=640x480:rate=${FPS}`,
    '-t', '30', '-c:v', 'libx264', '-preset', 'ultrafast', '-profile:v', 'baseline', '-g', `${FPS}`, '-pix_fmt', 'yuv420p',
    '-f', 'h264', '-y', clip]);
  assert.equal(made.status, 0, `ffmpeg could not make the recording: ${made.stderr}`);
  const v = await startVehicle(['--video-rtp', 'off', '--webrtc-signalling', '127.0.0.1:0'], {
    toml: `[camera]\nsource = "v4l2"\nfps = ${FPS}\n[camera.v4l2]\ndevice = "${clip}"\nformat = "h264"\n`,
    hmiToml: `allowed_origins = ["${origin}"]`,
  });
  try {
    const video = await json(`${v.url}api/video`);
    assert.equal(video.path.h264, 'camera', JSON.stringify(video));
    assert.equal(video.mjpeg, false, 'no JPEG pictures from an H.264 camera');
    const info = await json(`${v.url}api/webrtc`);
    const stream = info.streams[0];
    assert.deepEqual([stream.encode, stream.width, stream.height, stream.interval, stream.source],
      ['H264', 640, 480, `1/${FPS}`, 'camera-h264']);
    const page = await openViewer(`ws://127.0.0.1:${info.signalling_port}/`);
    const first = await until(async () => {
      const s = await viewerState(page);
      return s.frames > 0 && s;
    }, 20000, 'a first decoded frame of the camera\'s H.264');
    console.log(`camera's own H.264: first frame ${first.firstFrameMs} ms after opening the viewer`);
    const cam0 = (await json(`${v.url}camera/status`)).frames_total;
    const dec0 = (await viewerState(page)).frames;
    const t0 = Date.now();
    // Ten seconds, the vehicle's children looked at throughout: none.
    while (Date.now() - t0 < 10000) {
      assert.deepEqual(children(v.pid, null), [], 'the vehicle runs no child process');
      await new Promise((ok) => setTimeout(ok, 250));
    }
    const cam1 = (await json(`${v.url}camera/status`)).frames_total;
    const s = await viewerState(page);
    const decoded = s.frames - dec0;
    const made = cam1 - cam0;
    console.log(`10 s: the camera gave ${made} pictures, Chromium decoded ${decoded} (${(100 * decoded / made).toFixed(0)} %)`);
    assert.ok(made >= 30, `the camera gave only ${made} pictures in 10 s`);
    assert.ok(decoded >= 0.8 * made, `decoded ${decoded} of ${made} pictures`);
    assert.equal(s.width, 640);
    assert.equal(s.height, 480);
    assert.deepEqual(s.errors, []);
    const during = await json(`${v.url}api/video`);
    assert.equal(during.encoder_running, false);
    assert.deepEqual(during.h264, { route: 'camera', pid: null });
    // The HMI page plays it over WebRTC and never asks for MJPEG.
    const { page: hmi, context, problems } = await openPage(browser, v.url);
    await until(() => hmi.evaluate(() => window.neptunus.video.transport === 'webrtc' && window.neptunus.video.frames > 20),
      20000, 'the page playing the camera\'s H.264 over WebRTC');
    assert.equal((await json(`${v.url}camera/status`)).viewers, 0, 'nobody reads /video.mjpg');
    assert.deepEqual(children(v.pid, null), []);
    assert.deepEqual(problems, []);
    await context.close();
  } catch (e) {
    e.message += `\n--- neptunus stderr (tail) ---\n${v.stderr().slice(-3000)}`;
    throw e;
  } finally {
    await v.stop();
    rmSync(dir, { recursive: true, force: true });
  }
});

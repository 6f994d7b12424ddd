// The real Cockpit (Blue Robotics' ground station: its web build, from
// ../shared/cockpit/dist or COCKPIT_DIST; nothing of it is in this
// repository) against `neptunus`, shared by cockpit.test.js and the
// camera-to-screen bench (latency-bench.js).
//
// Cockpit derives everything from the vehicle's address alone: port 80 for
// mavlink2rest, the settings bag and the beacon, 6021 for the WebRTC
// signalling, 6020 for /streams. So the vehicle listens on port 80 of a
// loopback address of its own (127.0.X.Y: 127.0.0.0/8 all reaches this
// machine), which needs root or CAP_NET_BIND_SERVICE; a second vehicle
// elsewhere on the machine never collides with it. Cockpit's page is served
// here on a port of its own, and every request it makes to the internet
// (map tiles, fonts, analytics) is refused.
import { createServer } from 'node:http';
import { existsSync, readFileSync, statSync } from 'node:fs';
import { extname, join, resolve } from 'node:path';
import { chromium } from 'playwright-core';
import { CHROMIUM, REPO, startVehicle, until } from './harness.js';

export const DIST = resolve(process.env.COCKPIT_DIST || join(REPO, '..', 'shared', 'cockpit', 'dist'));

const TYPES = {
  '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.css': 'text/css',
  '.json': 'application/json', '.webmanifest': 'application/manifest+json', '.svg': 'image/svg+xml',
  '.png': 'image/png', '.avif': 'image/avif', '.ico': 'image/x-icon', '.wasm': 'application/wasm',
  '.woff': 'font/woff', '.woff2': 'font/woff2', '.ttf': 'font/ttf', '.glb': 'model/gltf-binary',
};

/** Why Cockpit cannot be run against a vehicle here, or null. */
export function cockpitMissing() {
  if (!existsSync(join(DIST, 'index.html'))) {
    return `Cockpit's web build is not at ${DIST}: set COCKPIT_DIST (the shared folder's cockpit/README.md says which commit and how it is built)`;
  }
  let unprivileged = 1024;
  try { unprivileged = Number(readFileSync('/proc/sys/net/ipv4/ip_unprivileged_port_start', 'utf8')); } catch { /* not Linux */ }
  if (process.getuid?.() !== 0 && unprivileged > 80) {
    return 'the vehicle must listen on port 80 (Cockpit derives every URL from the address alone): run as root, as the test command does';
  }
  return null;
}

/** Serves Cockpit's build (a single-page app: an unknown path is
 * index.html) on a free loopback port: `{ origin, close() }`. */
export async function serveCockpit() {
  const server = createServer((req, res) => {
    let file = join(DIST, decodeURIComponent(new URL(req.url, 'http://x').pathname));
    if (!file.startsWith(DIST) || !existsSync(file) || statSync(file).isDirectory()) file = join(DIST, 'index.html');
    res.writeHead(200, { 'content-type': TYPES[extname(file)] || 'application/octet-stream' });
    res.end(readFileSync(file));
  });
  await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
  return { origin: `http://127.0.0.1:${server.address().port}`, close: () => server.close() };
}

/** Chromium as Cockpit needs it: its WebRTC video plays without a gesture. */
export function launchCockpitBrowser() {
  return chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--autoplay-policy=no-user-gesture-required',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
}

/** The vehicle on port 80 of a loopback address of its own (`ip`, else a
 * random 127.0.X.Y, another one tried when one is taken), with Cockpit's
 * `origin` allowed, `--video-rtp off`, `toml` as its config file and
 * `hmiToml` more of its [hmi] section; `password`: the pilot password to
 * set first. Resolves once the camera manager's ports (6021, 6020) are
 * listening beside it: the vehicle with `ip`. */
export async function cockpitVehicle(dataDir, { origin, ip, toml, hmiToml = '', password } = {}) {
  for (let attempt = 0; ; attempt++) {
    const at = ip || `127.0.${2 + Math.floor(Math.random() * 250)}.${2 + Math.floor(Math.random() * 250)}`;
    let v;
    try {
      v = await startVehicle(['--video-rtp', 'off'], {
        http: `${at}:80`,
        password,
        dataDir,
        toml,
        hmiToml: `allowed_origins = ["${origin}"]\n${hmiToml}`,
      });
    } catch (e) {
      if (ip || attempt >= 4) throw e;
      continue;
    }
    const beside = await until(() => {
      const log = v.stderr();
      return log.includes(`on ws://${at}:6021/`) && log.includes(`on http://${at}:6020/streams`) ? true : null;
    }, 20000, 'the signalling (6021) and /streams (6020)').catch(() => null);
    if (beside) return { ...v, ip: at };
    await v.stop();
    if (ip || attempt >= 4) throw new Error(`ports 6020/6021 on ${at} were taken`);
  }
}

/** A browser context as a new user's browser: Cockpit given the vehicle's
 * address (and past its first-run screens: the tutorial, the splash), the
 * internet refused, no service worker. */
export async function cockpitContext(browser, ip, viewport) {
  const context = await browser.newContext({ viewport, serviceWorkers: 'block' });
  await context.route('**/*', (route) => {
    const host = new URL(route.request().url()).hostname;
    return host === '127.0.0.1' || host === ip ? route.continue() : route.abort();
  });
  await context.addInitScript((address) => {
    if (location.port === '80' || location.port === '') return; // the vehicle's own page
    localStorage.setItem('cockpit-vehicle-address', address);
    localStorage.setItem('cockpit-has-seen-tutorial', 'true');
    localStorage.setItem('cockpit-show-splash-screen-on-startup', 'false');
    localStorage.setItem('cockpit-prevent-auto-vehicle-discovery-dialog', 'true');
    // Headless Chromium has no speech voices: Cockpit would say so.
    localStorage.setItem('cockpit-enable-voice-alerts', 'false');
  }, ip);
  return context;
}

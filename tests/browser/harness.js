// Shared by the browser tests and the screenshot script: the real
// `neptunus --sim` binary (or `--hil`: NEPTUNUS_HIL_FIRMWARE) with its HMI
// on a free loopback port, and Debian's Chromium driven by playwright-core
// (never a browser a tool downloads).
import { spawn, spawnSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, existsSync, openSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = dirname(fileURLToPath(import.meta.url));
export const REPO = resolve(here, '..', '..');
export const BIN = process.env.NEPTUNUS_BIN || join(REPO, 'target', 'debug', 'neptunus');
export const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
// With the genuine firmware in the loop (`neptunus --hil`): the firmware's
// built .elf (`neptunus genuine-board --build-only`), else the emulator
// (`--sim`) — the interoperability suite's convention (its conftest.py).
export const HIL_FIRMWARE = process.env.NEPTUNUS_HIL_FIRMWARE || null;

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Polls `fn` until it returns a truthy value or `ms` pass. */
export async function until(fn, ms, what) {
  const end = Date.now() + ms;
  let last;
  while (Date.now() < end) {
    last = await fn();
    if (last) return last;
    await sleep(50);
  }
  throw new Error(`timed out after ${ms} ms waiting for ${what} (last: ${JSON.stringify(last)})`);
}

/** `neptunus --sim` (or `--hil` with NEPTUNUS_HIL_FIRMWARE) with its HMI on
 * 127.0.0.1:0; resolves once the page is served.
 * `password`: set first with `neptunus hmi set-password` (piped, as a script
 * would); `hmiToml`: the body of an `[hmi]` section of a config file. */
export async function startVehicle(extraArgs = [], { password, hmiToml, toml, http = '127.0.0.1:0', dataDir } = {}) {
  if (!existsSync(BIN)) throw new Error(`no neptunus binary at ${BIN}: run \`cargo build\` or set NEPTUNUS_BIN`);
  const dir = mkdtempSync(join(tmpdir(), 'neptunus-browser-'));
  const data = dataDir || join(dir, 'data');
  if (password) {
    const r = spawnSync(BIN, ['hmi', 'set-password', '--data-dir', data], { input: `${password}\n`, encoding: 'utf8' });
    if (r.status !== 0) throw new Error(`neptunus hmi set-password failed: ${r.stderr}`);
  }
  if (hmiToml || toml) {
    const config = join(dir, 'neptunus.toml');
    writeFileSync(config, `${toml || ''}\n${hmiToml ? `[hmi]\n${hmiToml}\n` : ''}`);
    extraArgs = [...extraArgs, '--config', config];
  }
  // A restarted vehicle writes its address again: wait for the new one.
  rmSync(join(data, 'http.addr'), { force: true });
  const log = openSync(join(dir, 'stderr.txt'), 'w');
  const board = HIL_FIRMWARE ? ['--hil', HIL_FIRMWARE] : ['--sim'];
  const child = spawn(
    BIN,
    [...board, '--data-dir', data, '--http', http, '--mavlink', 'udpin:127.0.0.1:0', ...extraArgs],
    { stdio: ['ignore', log, log], env: { ...process.env, NO_COLOR: '1', RUST_LOG: process.env.RUST_LOG || 'info' } },
  );
  let exited = null;
  child.on('exit', (code) => { exited = code; });
  const addr = await until(() => {
    if (exited !== null) throw new Error(`neptunus exited (${exited}): ${readFileSync(join(dir, 'stderr.txt'), 'utf8').slice(-2000)}`);
    try { return readFileSync(join(data, 'http.addr'), 'utf8').trim(); } catch { return null; }
  }, 30000, 'the HMI address file');
  return {
    url: `http://${addr}/`,
    pid: child.pid,
    dir,
    stderr: () => readFileSync(join(dir, 'stderr.txt'), 'utf8'),
    async stop() {
      if (exited === null) {
        child.kill('SIGTERM');
        await until(() => exited !== null, 5000, 'neptunus to exit').catch(() => child.kill('SIGKILL'));
      }
      rmSync(dir, { recursive: true, force: true });
    },
  };
}

// playwright-core starts Chromium with a fresh temporary profile of its own
// (the --user-data-dir the machine notes ask for) and removes it on close.
export async function launchBrowser() {
  return chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
  });
}

/** A page on the HMI that records console errors and failed requests.
 * `initScript`: run in the page before its own scripts (the gamepad tests'
 * stand-in for `navigator.getGamepads`). */
export async function openPage(browser, url, viewport = { width: 1280, height: 800 }, { initScript } = {}) {
  const context = await browser.newContext({ viewport, acceptDownloads: true });
  if (initScript) await context.addInitScript(initScript);
  const page = await context.newPage();
  const problems = [];
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('requestfailed', (r) => {
    // The video stream is cut when the page closes; that is no failure.
    // A navigation aborts the stream and the page's video-path request.
    if (!r.url().endsWith('/video.mjpg') && !(r.url().endsWith('/api/video') && r.failure()?.errorText === 'net::ERR_ABORTED')) problems.push(`request failed: ${r.url()} ${r.failure()?.errorText}`);
  });
  page.on('response', (r) => { if (r.status() >= 400) problems.push(`HTTP ${r.status()}: ${r.url()}`); });
  await page.goto(url);
  await until(() => page.evaluate(() => !!(window.neptunus && window.neptunus.state.t && window.neptunus.state.t.vehicle_seen)), 20000, 'telemetry in the page');
  return { context, page, problems };
}

/** Runs `body` with a fresh `startVehicle(args, opts)`; adds the vehicle's
 * log tail to a failure, and stops the vehicle whatever happens. */
export async function withVehicle(body, args = [], opts = {}) {
  const v = await startVehicle(args, opts);
  try {
    await body(v);
  } catch (e) {
    e.message += `\n--- neptunus stderr (tail) ---\n${v.stderr().slice(-3000)}`;
    throw e;
  } finally {
    await v.stop();
  }
}

/** The genuine board's runner (`--hil`) reports every 10 s in the
 * vehicle's log: simavr's share of real time over its last second, its
 * slips so far (each a fall more than 250 ms behind, let go), and the
 * longest the coupling of board and plant waited since the report before. */
export function runnerReports(log) {
  return [...log.matchAll(/genuine board in simavr.*?realtime_ratio=([\d.]+).*?slips=(\d+).*?widest_gap_ms=(\d+)/g)]
    .map((m) => ({ ratio: Number(m[1]), slips: Number(m[2]), gapMs: Number(m[3]) }));
}

/** A control outcome is judged only where the board's world kept pace
 * with the vehicle's clock: with the genuine firmware in simavr on a busy
 * machine the board and the plant run slower than the vehicle, which no
 * autopilot tuned for the water can be judged by. The thresholds are
 * tests/hil_rov.rs's; unlike its tight 30-s hold, a check with a margin of
 * decimetres is not voided by a slip (a stall of a few hundred ms, seen
 * with nothing but the test's own browser beside it), only by a slow
 * world or a long coupling gap. */
const MIN_REALTIME_RATIO = 0.85;
const MAX_COUPLING_GAP_MS = 250;

/** Whether the board's world kept pace from `mark` (a length of the
 * vehicle's log) to now: always under `--sim`; under `--hil`, judged by the
 * runner's reports from then to its next one (waited for). */
export async function boardKeptPace(v, mark) {
  if (!HIL_FIRMWARE) return { kept: true, why: 'the built-in simulator' };
  const end = v.stderr().length;
  await until(() => runnerReports(v.stderr().slice(end)).length > 0, 20000, "the board runner's next report");
  const during = runnerReports(v.stderr().slice(mark));
  const kept = during.length > 0
    && during.every((r) => r.ratio >= MIN_REALTIME_RATIO && r.gapMs <= MAX_COUPLING_GAP_MS);
  return { kept, why: JSON.stringify(during) };
}

/** The latest telemetry the page holds. */
export const telemetry = (page) => page.evaluate(() => window.neptunus.state.t);

/** Waits until the vehicle is ready to arm, requests control and arms —
 * again, as a pilot would, while the vehicle refuses: its pre-arm checks
 * can fail for a moment after they passed (a board slowed down by a busy
 * machine, the genuine firmware in simavr above all, reports late). */
export async function takeControlAndArm(page) {
  await until(async () => (await telemetry(page)).health?.prearm, 20000, 'pre-arm checks');
  await page.click('[data-testid=request-control]');
  await until(async () => (await telemetry(page)).control.you, 10000, 'control');
  const end = Date.now() + 60000;
  for (;;) {
    await until(async () => (await telemetry(page)).health?.prearm, Math.max(end - Date.now(), 1000), 'pre-arm checks before arming');
    await page.click('[data-testid=arm]');
    try {
      await until(async () => (await telemetry(page)).armed, 10000, 'armed');
      return;
    } catch (e) {
      if (Date.now() >= end) throw e;
    }
  }
}

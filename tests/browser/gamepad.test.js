// The gamepad, tested against the real binary (`--sim`)
// in Debian's headless Chromium. A headless browser has no gamepad, so the
// one stand-in is `navigator.getGamepads`, replaced before the page's
// scripts run by a fake pad the test presses; everything after it — the
// page, the WebSocket, the server's authority check and the vehicle — is
// the real thing. Waits poll a condition with a deadline.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { launchBrowser, openPage, telemetry, until, withVehicle } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

/** Runs in the page before its scripts: a standard-mapping pad that, as in
 * Chromium, is only listed once one of its buttons was pressed. */
function fakePad() {
  const pad = {
    id: 'Test pad (STANDARD GAMEPAD Vendor: 045e Product: 028e)',
    index: 0,
    connected: true,
    mapping: 'standard',
    timestamp: 0,
    axes: [0, 0, 0, 0],
    buttons: Array.from({ length: 17 }, () => ({ pressed: false, touched: false, value: 0 })),
  };
  let shown = false;
  Object.defineProperty(Navigator.prototype, 'getGamepads', {
    configurable: true,
    value: () => [shown ? pad : null, null, null, null],
  });
  const set = (on, idx) => {
    shown = true;
    for (const i of idx) pad.buttons[i] = { pressed: on, touched: on, value: on ? 1 : 0 };
    pad.timestamp += 1;
  };
  window.testPad = {
    press: (...idx) => set(true, idx),
    release: (...idx) => set(false, idx),
    axis: (i, v) => { shown = true; pad.axes[i] = v; pad.timestamp += 1; },
  };
}

const open = (v, viewport) => openPage(browser, v.url, viewport, { initScript: fakePad });
const press = (page, ...idx) => page.evaluate((i) => window.testPad.press(...i), idx);
const release = (page, ...idx) => page.evaluate((i) => window.testPad.release(...i), idx);
/** Lets a few animation frames pass, so the page has read the pad. */
const frames = (page, n = 3) => page.evaluate((k) => new Promise((res) => {
  const step = () => (--k <= 0 ? res() : requestAnimationFrame(step));
  requestAnimationFrame(step);
}), n);
/** Presses and releases, each held for a few frames. */
async function tap(page, ...idx) {
  await press(page, ...idx);
  await frames(page);
  await release(page, ...idx);
  await frames(page);
}

async function gamepadPilot(page) {
  await until(async () => (await telemetry(page)).health?.prearm, 20000, 'pre-arm checks');
  await page.check('input[name=input][value=gamepad]');
  await page.click('[data-testid=request-control]');
  await until(async () => (await telemetry(page)).control.you, 10000, 'control');
}

test('the gamepad panel shows the connection, the axes and the buttons live', () => withVehicle(async (v) => {
  const { page, context, problems } = await open(v);
  assert.match(await page.textContent('[data-testid=pad-status]'), /no gamepad: press a button on it/);
  await press(page, 0);
  await until(async () => /Test pad/.test(await page.textContent('[data-testid=pad-status]')), 5000, 'the pad named');
  assert.equal(await page.locator('#pad-buttons .pad-btn').count(), 17);
  assert.equal(await page.locator('#pad-axes .pad-axis').count(), 4);
  await until(() => page.locator('#pad-buttons .pad-btn[data-button="0"].on').count(), 5000, 'button A lit');
  await release(page, 0);
  await until(async () => (await page.locator('#pad-buttons .pad-btn.on').count()) === 0, 5000, 'button A dark');
  await page.evaluate(() => window.testPad.axis(3, -0.8));
  const fill = page.locator('#pad-axes .pad-axis[data-axis="3"] i');
  await until(async () => (await fill.getAttribute('style'))?.includes('width: 40%'), 5000, 'axis 3 drawn at -0.8');
  assert.match(await fill.getAttribute('style'), /left: 10%/);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the button map starts as ArduSub\'s, is kept across a reload, and resets to ArduSub\'s', () => withVehicle(async (v) => {
  const { page, context, problems } = await open(v);
  await page.click('[data-testid=pad-map-toggle]');
  const value = (i) => page.inputValue(`[data-testid=pad-map] select[data-button="${i}"]`);
  // ArduSub's defaults, on the same physical buttons (W3C standard numbering).
  const ardusub = {
    0: 'none', 1: 'mode:MANUAL', 2: 'mode:ALT_HOLD', 3: 'mode:STABILIZE', 4: 'tilt_down', 5: 'tilt_up',
    8: 'disarm', 9: 'arm', 10: 'tilt_centre', 11: 'none', 12: 'gain_up', 13: 'gain_down',
    14: 'lights_down', 15: 'lights_up', 16: 'none',
  };
  for (const [i, f] of Object.entries(ardusub)) assert.equal(await value(i), f, `button ${i}`);
  // Every offered mode and every function can be picked.
  const options = await page.$$eval('[data-testid=pad-map] select[data-button="0"] option', (o) => o.map((x) => x.value));
  for (const f of ['none', 'arm', 'disarm', 'mode:MANUAL_THRUSTERS', 'mode:MANUAL', 'mode:STABILIZE', 'mode:ALT_HOLD',
    'mode:SURFACE', 'gain_up', 'gain_down', 'lights_up', 'lights_down', 'tilt_up', 'tilt_down', 'tilt_centre', 'laser',
    'request_control']) {
    assert.ok(options.includes(f), `function ${f} offered: ${options}`);
  }
  await page.selectOption('[data-testid=pad-map] select[data-button="3"]', 'laser');
  await page.selectOption('[data-testid=pad-map] select[data-button="9"]', 'none');
  await page.reload();
  await until(async () => (await telemetry(page))?.vehicle_seen, 20000, 'telemetry after the reload');
  await page.click('[data-testid=pad-map-toggle]');
  assert.equal(await value(3), 'laser');
  assert.equal(await value(9), 'none');
  assert.equal(await value(8), 'disarm');
  await page.click('[data-testid=pad-reset]');
  assert.equal(await value(3), 'mode:STABILIZE');
  assert.equal(await value(9), 'arm');
  await page.reload();
  await until(async () => (await telemetry(page))?.vehicle_seen, 20000, 'telemetry after the second reload');
  await page.click('[data-testid=pad-map-toggle]');
  assert.equal(await value(9), 'arm');
  // A damaged store is no crash: not JSON gives ArduSub's map; unknown
  // functions and buttons are dropped, the rest kept.
  const reopen = async (stored) => {
    await page.evaluate((x) => localStorage.setItem('neptunus.gamepad.buttons.v1', x), stored);
    await page.reload();
    await until(async () => (await telemetry(page))?.vehicle_seen, 20000, 'telemetry after a reload');
    await page.click('[data-testid=pad-map-toggle]');
  };
  await reopen('{not json');
  assert.equal(await value(9), 'arm');
  await reopen(JSON.stringify({ 9: 'launch', 3: 'laser', '-1': 'arm', x: 'arm', 2: 42, 1: 'mode:<b>', 0: 'mode:POSHOLD' }));
  assert.equal(await value(9), 'none');
  // A mode from another vehicle's map is kept, and said to be not offered here.
  assert.equal(await value(0), 'mode:POSHOLD');
  assert.match(await page.locator('[data-testid=pad-map] select[data-button="0"] option:checked').textContent(), /POSHOLD \(not offered here\)/);
  assert.equal(await value(3), 'laser');
  assert.equal(await value(2), 'none');
  assert.equal(await value(1), 'none');
  assert.deepEqual(problems, []);
  await context.close();
}));

test('Start arms the real vehicle, Back disarms it; a held button acts once; nothing while typing or in keyboard mode', () => withVehicle(async (v) => {
  const { page, context, problems } = await open(v);
  await gamepadPilot(page);
  // The pad was first seen with Start already held: that is no press.
  await press(page, 9);
  await frames(page, 10);
  assert.equal((await telemetry(page)).armed, false, 'a button held when the pad appeared does nothing');
  await release(page, 9);
  await frames(page);
  await tap(page, 9);
  await until(async () => (await telemetry(page)).armed, 10000, 'armed by Start');
  // D-pad up held: the gain goes up one step, once.
  const gain0 = (await telemetry(page)).gain;
  await press(page, 12);
  await until(async () => (await telemetry(page)).gain > gain0 + 0.01, 10000, 'gain up');
  await page.waitForTimeout(600);
  await release(page, 12);
  await frames(page);
  const gain1 = (await telemetry(page)).gain;
  assert.ok(Math.abs(gain1 - Math.min(1, gain0 + 0.1)) < 1e-3, `one step: ${gain0} -> ${gain1}`);
  // Typing in a field: Back does nothing.
  await page.click('#ap-depth');
  await tap(page, 8);
  await page.waitForTimeout(500);
  assert.equal((await telemetry(page)).armed, true, 'Back while typing did not disarm');
  await page.keyboard.press('Escape');
  // Keyboard input mode: the pad's buttons are not the pilot's input.
  await page.check('input[name=input][value=keyboard]');
  await tap(page, 8);
  await page.waitForTimeout(500);
  assert.equal((await telemetry(page)).armed, true, 'Back in keyboard mode did not disarm');
  await page.check('input[name=input][value=gamepad]');
  await tap(page, 8);
  await until(async () => !(await telemetry(page)).armed, 10000, 'disarmed by Back');
  // B: MANUAL, X: depth hold, by ArduSub's map.
  await tap(page, 2);
  await until(async () => (await telemetry(page)).mode === 2, 10000, 'ALT_HOLD from X');
  await tap(page, 1);
  await until(async () => (await telemetry(page)).mode === 19, 10000, 'MANUAL from B');
  assert.deepEqual(problems, []);
  await context.close();
}));

test('a remapped button does its new job', () => withVehicle(async (v) => {
  const { page, context } = await open(v);
  await page.click('[data-testid=pad-map-toggle]');
  await page.selectOption('[data-testid=pad-map] select[data-button="3"]', 'laser');
  await page.selectOption('[data-testid=pad-map] select[data-button="0"]', 'lights_up');
  await page.click('[data-testid=pad-map-toggle]');
  await gamepadPilot(page);
  await tap(page, 11); // the pad shows itself (unmapped: R stick click)
  await tap(page, 3);
  await until(async () => (await telemetry(page)).laser === true, 10000, 'laser on from Y');
  await tap(page, 3);
  await until(async () => (await telemetry(page)).laser === false, 10000, 'laser off from Y');
  await tap(page, 0);
  await until(async () => (await telemetry(page)).lights > 0, 10000, 'lights up from A');
  await context.close();
}));

test('the owner hands control over with the LB + RB + A chord; no single button does', () => withVehicle(async (v) => {
  const a = await open(v);
  const b = await openPage(browser, v.url);
  const prompted = () => a.page.isVisible('[data-testid=request-dialog]');
  /** B asks for control: a request again while one is open gives the
   * owner a fresh 10 s to answer. */
  const ask = async () => {
    await b.page.click('[data-testid=request-control]');
    await a.page.waitForSelector('[data-testid=request-dialog]:not([hidden])', { timeout: 10000 });
  };
  try {
    await gamepadPilot(a.page);
    await tap(a.page, 11); // the pad shows itself (unmapped: R stick click)
    await ask();
    assert.match(await a.page.textContent('[data-testid=request-chord]'), /LB \+ RB.*A/);
    assert.ok(await a.page.isVisible('[data-testid=request-chord]'));
    // Every button alone, then two of the three: no handover, and LB and RB
    // (the camera's tilt otherwise) do not tilt while they may be half a
    // chord. A few at a time under a fresh request, each few judged only if
    // the prompt stayed open through them: the request runs out after 10 s,
    // and a busy machine can take that long — then they are tapped again.
    const taps = [...Array(17).keys()].map((i) => [i]).concat([[4, 5], [4, 0], [5, 0]]);
    for (let k = 0; k < taps.length; k += 5) {
      const few = taps.slice(k, k + 5);
      for (let attempt = 1; ; attempt++) {
        await ask();
        const tilt0 = (await telemetry(a.page)).tilt;
        for (const t of few) await tap(a.page, ...t);
        await a.page.waitForTimeout(500);
        assert.equal((await telemetry(a.page)).control.you, true, `A still in control after ${JSON.stringify(few)}`);
        if (await prompted()) {
          const tilt1 = (await telemetry(a.page)).tilt;
          assert.ok(Math.abs(tilt1 - tilt0) < 1e-3, `tilt unchanged by ${JSON.stringify(few)} while the prompt is open: ${tilt0} -> ${tilt1}`);
          break;
        }
        assert.ok(attempt < 3, `the prompt ran out during ${JSON.stringify(few)} three times`);
        // Without the prompt LB and RB may have tilted the camera: centred
        // again (L stick click, no chord button), as it was at the start.
        await tap(a.page, 10);
        await a.page.waitForTimeout(1000);
      }
    }
    // Hold LB + RB, then press A.
    await ask();
    await press(a.page, 4, 5);
    await frames(a.page);
    await press(a.page, 0);
    await until(async () => (await telemetry(b.page)).control.you, 10000, 'B in control');
    await release(a.page, 0, 4, 5);
    assert.ok(await a.page.isHidden('[data-testid=request-dialog]'));
  } finally {
    await a.context.close();
    await b.context.close();
  }
}));

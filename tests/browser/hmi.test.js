// Browser tests of the Neptunus HMI: the real binary (`--sim`) and Debian's
// headless Chromium through playwright-core. Waits poll a condition with a
// deadline; nothing sleeps to let time pass.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { createServer } from 'node:http';
import { launchBrowser, openPage, telemetry, takeControlAndArm, until, withVehicle } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

test('the page loads with no console errors and shows the video', () => withVehicle(async (v) => {
  const { page, problems, context } = await openPage(browser, v.url);
  await page.waitForTimeout(0);
  await until(() => page.isVisible('#video'), 10000, 'the video image (the synthetic camera runs with --sim)');
  assert.equal(await page.isVisible('[data-testid=no-video]'), false);
  assert.equal(await page.isVisible('[data-testid=attitude]'), true);
  // Loopback may pilot without a password; the id is lent at the first command.
  assert.match(await page.textContent('[data-testid=me]'), /you may pilot/);
  assert.equal(await page.isVisible('[data-testid=login]'), false);
  assert.equal(await page.isVisible('[data-testid=watch-only]'), false);
  // A frame of telemetry reaches the HUD: the mode has a name.
  await until(async () => (await page.textContent('[data-testid=mode-name]')) !== '—', 10000, 'the mode on the HUD');
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the video gets frames', async () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  const video = await page.evaluate(async () => (await fetch('/api/video')).json());
  assert.equal(video.available, true, `the synthetic camera serves /video.mjpg with --sim: ${JSON.stringify(video)}`);
  await until(() => page.evaluate(() => window.neptunus.video.frames > 0 && document.getElementById('video').width > 0), 15000, 'a video frame');
  // Frames keep coming: the camera reports a frame rate and a fresh frame.
  const status = await until(async () => {
    const s = await page.evaluate(async () => (await fetch('/camera/status')).json());
    return s.frames_total >= 5 && s;
  }, 15000, 'five frames');
  assert.ok(status.frame_age_ms < 2000, `latest frame ${status.frame_age_ms} ms old`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('holding W moves the simulated ROV forward; window blur stops it', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  await takeControlAndArm(page);
  const start = await until(async () => (await telemetry(page)).sim, 10000, 'simulated state');
  await page.keyboard.down('KeyW');
  const moving = await until(async () => {
    const t = await telemetry(page);
    return t.sim.surge_mps > 0.05 && t.thrusters_us.starboard !== 1500 && t;
  }, 20000, 'surge from holding W');
  assert.ok(moving.sim.north_m !== start.north_m, 'the ROV moved');
  // The operator looks away: the page stops and tells the vehicle.
  await page.evaluate(() => window.dispatchEvent(new Event('blur')));
  await until(async () => {
    const t = await telemetry(page);
    const u = t.thrusters_us;
    return u.port === 1500 && u.vertical === 1500 && u.starboard === 1500;
  }, 10000, 'neutral thrusters after blur');
  await page.keyboard.up('KeyW');
  assert.deepEqual(problems, []);
  await context.close();
}));

test('manual-thruster mode drives one thruster', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  await takeControlAndArm(page);
  await page.check('input[name=mode][value="100"]');
  await until(async () => (await telemetry(page)).mode === 100, 10000, 'MANUAL_THRUSTERS mode');
  await page.keyboard.down('KeyQ'); // port thruster forward
  const t = await until(async () => {
    const x = await telemetry(page);
    return x.thrusters_us.port !== 1500 && x;
  }, 15000, 'the port thruster');
  assert.equal(t.thrusters_us.starboard, 1500);
  assert.equal(t.thrusters_us.vertical, 1500);
  await page.keyboard.up('KeyQ');
  await until(async () => (await telemetry(page)).thrusters_us.port === 1500, 10000, 'port back to neutral');
  await context.close();
}));

test('a second browser requests control and the first accepts in its prompt', () => withVehicle(async (v) => {
  const a = await openPage(browser, v.url);
  const b = await openPage(browser, v.url);
  await until(async () => (await telemetry(a.page)).health?.prearm, 20000, 'ready');
  await a.page.click('[data-testid=request-control]');
  await until(async () => (await telemetry(a.page)).control.you, 10000, 'A in control');
  await b.page.click('[data-testid=request-control]');
  await a.page.waitForSelector('[data-testid=request-dialog]:not([hidden])', { timeout: 10000 });
  assert.match(await a.page.textContent('#request-text'), /GCS 201 asks for control/);
  await a.page.click('[data-testid=accept]');
  await until(async () => (await telemetry(b.page)).control.you, 10000, 'B in control');
  assert.match(await b.page.textContent('[data-testid=who]'), /you/);
  await until(async () => !(await telemetry(a.page)).control.you, 10000, 'A no longer in control');
  await a.context.close();
  await b.context.close();
}));

test('developer interface: 10 plots, an 11th refused, reset clears data, CSV export', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  await page.click('[data-testid=dev-toggle]');
  const options = await page.$$eval('#signal option', (o) => o.map((x) => x.value));
  assert.ok(options.length >= 30, `signals: ${options.length}`);
  for (const s of ['depth_m', 'roll_deg', 'pitch_deg', 'heading_deg', 'voltage_v', 'current_a', 'cmd_surge', 'starboard_us', 'est_depth_m', 'sp_depth_m', 'sim_x_m', 'sim_r_dps']) {
    assert.ok(options.includes(s), `signal ${s} offered`);
  }
  for (const s of options.slice(0, 10)) {
    await page.selectOption('#signal', s);
    await page.click('[data-testid=add-plot]');
  }
  assert.equal(await page.locator('#plots .plot').count(), 10);
  await page.selectOption('#signal', options[10]);
  await page.click('[data-testid=add-plot]');
  assert.equal(await page.locator('#plots .plot').count(), 10);
  assert.match(await page.textContent('[data-testid=plot-note]'), /At most 10 plots/);
  // Remove one, and an 11th signal fits again.
  await page.locator('#plots .plot .remove-plot').first().click();
  await page.click('[data-testid=add-plot]');
  assert.equal(await page.locator('#plots .plot').count(), 10);
  await until(() => page.evaluate(() => window.neptunus.recorder.length > 20), 10000, 'recorded samples');
  // What Reset guarantees: nothing recorded before it is kept. Clicked and
  // read in one task of the page, so no sample can arrive in between
  // however busy the machine is.
  const after = await page.evaluate(() => {
    document.querySelector('[data-testid=reset-data]').click();
    return window.neptunus.recorder.length;
  });
  assert.equal(after, 0, 'samples recorded before Reset are gone');
  await until(() => page.evaluate(() => window.neptunus.recorder.length > 5), 10000, 'recording again');
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('[data-testid=export-csv]')]);
  const csv = readFileSync(await download.path(), 'utf8');
  const lines = csv.trim().split('\n');
  assert.match(lines[0], /^t_s,depth_m,/);
  assert.ok(lines.length > 5, `csv rows: ${lines.length}`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('logger category filters', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  await page.click('[data-testid=dev-toggle]');
  await page.uncheck('#categories input[data-category=stop]');
  await page.evaluate(() => window.dispatchEvent(new Event('blur')));
  await page.click('[data-testid=request-control]');
  await until(() => page.locator('#log li[data-category=control]').count(), 10000, 'a control entry');
  // The vehicle's own text about it, filed under the category the core gave it.
  await until(() => page.locator('#log li[data-category=control]').filter({ hasText: 'in control (was' }).count(),
    10000, "the core's control text in the control category");
  assert.equal(await page.locator('#log li[data-category=stop]').count(), 0);
  await page.check('#categories input[data-category=stop]');
  assert.ok(await page.locator('#log li[data-category=stop]').count() > 0);
  await page.uncheck('#categories input[data-category=control]');
  assert.equal(await page.locator('#log li[data-category=control]').count(), 0);
  const text = await page.textContent('#log li[data-category=stop]');
  assert.match(text, /^\d\d:\d\d:\d\d\.\d{3} \[stop\]/);
  await context.close();
}));

for (const viewport of [{ width: 1024, height: 768 }, { width: 768, height: 1024 }]) {
  test(`tablet ${viewport.width}x${viewport.height} shows every control`, () => withVehicle(async (v) => {
    const { page, context } = await openPage(browser, v.url, viewport);
    await page.click('[data-testid=dev-toggle]');
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    assert.ok(overflow <= 0, `horizontal overflow of ${overflow} px`);
    const selectors = [
      '[data-testid=request-control]', '[data-testid=release-control]', '[data-testid=arm]', '[data-testid=disarm]',
      'input[name=input][value=keyboard]', 'input[name=input][value=touch]', 'input[name=input][value=gamepad]',
      'input[name=input][value=headtracking]', 'input[name=mode][value="100"]', 'input[name=mode][value="19"]',
      'input[name=mode][value="0"]', 'input[name=mode][value="2"]', '[data-testid=surface]',
      'input[name=run][value=normal]', 'input[name=run][value=simulator]', '#ap-depth', '#ap-heading',
      '#gain', '#lights', '#tilt', '#laser', '[data-testid=attitude]', '#video',
      '#touchpad .tp[data-key=KeyW]', '[data-testid=dev-toggle]', '[data-testid=who]', '[data-testid=link]',
      '[data-testid=failsafe]', '[data-testid=add-plot]', '[data-testid=reset-data]', '[data-testid=export-csv]',
      '#categories input[data-category=failsafe]',
    ];
    for (const sel of selectors) {
      const el = page.locator(sel).first();
      await el.scrollIntoViewIfNeeded();
      assert.ok(await el.isVisible(), `${sel} visible`);
      const box = await el.boundingBox();
      assert.ok(box && box.x >= 0 && box.x + box.width <= viewport.width + 0.5, `${sel} within the width: ${JSON.stringify(box)}`);
    }
    await context.close();
  }));
}

test('with a pilot password and open_control "none" the pilot logs in with the form, then arms', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  // Watching: the banner says why, the form is there.
  assert.match(await page.textContent('[data-testid=watch-only]'), /log in with the pilot password/);
  assert.match(await page.textContent('[data-testid=me]'), /watching/);
  assert.equal(await page.isVisible('[data-testid=login]'), true);
  await page.fill('[data-testid=password]', 'not-the-password');
  await page.click('[data-testid=login-submit]');
  await until(async () => /wrong pilot password/.test(await page.textContent('[data-testid=login-note]')), 10000, 'the wrong-password message');
  await page.fill('[data-testid=password]', 'tide-pool-42');
  await page.click('[data-testid=login-submit]');
  await until(async () => /logged in/.test(await page.textContent('[data-testid=me]')), 10000, 'the logged-in session');
  assert.match(await page.textContent('[data-testid=me]'), /GCS 200/);
  assert.equal(await page.isVisible('[data-testid=login]'), false);
  assert.equal(await page.isVisible('[data-testid=watch-only]'), false);
  // The cookie is HttpOnly: the page's script cannot read it.
  assert.equal(await page.evaluate(() => document.cookie), '');
  await takeControlAndArm(page);
  // A reload keeps the login (the cookie goes with the new WebSocket).
  await page.reload();
  await until(async () => /GCS \d+ \(logged in\)/.test(await page.textContent('[data-testid=me]')), 10000, 'logged in after a reload');
  await page.click('[data-testid=logout]');
  await until(async () => /watching/.test(await page.textContent('[data-testid=me]')), 10000, 'watching after logging out');
  await context.close();
}, [], { password: 'tide-pool-42', hmiToml: 'open_control = "none"' }));

test('a page from another origin can neither open the WebSocket nor POST, and the vehicle never arms', () => withVehicle(async (v) => {
  const hmi = new URL(v.url);
  // The attacker's page, served from another loopback port (another origin).
  const evilPage = `<!doctype html><script>
    window.result = { ws: 'pending', post: 'pending' };
    const ws = new WebSocket('ws://${hmi.host}/ws');
    ws.onopen = () => {
      window.result.ws = 'open';
      for (const m of [{ type: 'request_control' }, { type: 'arm', arm: true }]) ws.send(JSON.stringify(m));
      setInterval(() => ws.send(JSON.stringify({ type: 'sticks', surge: 1, heave_up: 0, yaw: 0 })), 50);
    };
    ws.onerror = () => { if (window.result.ws === 'pending') window.result.ws = 'refused'; };
    fetch('http://${hmi.host}/api/login', { method: 'POST', mode: 'no-cors', body: '{"password":"guess"}' })
      .then(() => { window.result.post = 'sent'; }, () => { window.result.post = 'failed'; });
  </script>`;
  const server = createServer((req, res) => { res.writeHead(200, { 'Content-Type': 'text/html' }); res.end(evilPage); });
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  try {
    const context = await browser.newContext();
    const page = await context.newPage();
    await page.goto(`http://127.0.0.1:${server.address().port}/`);
    const result = await until(() => page.evaluate(() => window.result.ws !== 'pending' && window.result.post !== 'pending' && window.result), 10000, 'the attack to finish');
    assert.equal(result.ws, 'refused', JSON.stringify(result));
    // The HMI counted both refusals (the no-cors POST's answer is opaque to
    // the page, so ask the HMI), and the vehicle is disarmed and unowned.
    const status = await (await fetch(new URL('/api/status', v.url))).json();
    assert.ok(status.refused_requests >= 2, JSON.stringify(status));
    assert.equal(status.telemetry.armed, false);
    assert.equal(status.telemetry.control.owner, null);
    assert.equal(status.sessions_free, status.sessions_max);
    assert.equal(status.watchers, 0);
    await context.close();
  } finally {
    server.close();
  }
}));

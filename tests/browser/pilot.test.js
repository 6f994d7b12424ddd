// The pilot's view, tested as a pilot meets it: the real binary
// (`--sim`) and Debian's headless Chromium. Each test is one defect a pilot
// at the pool side saw; waits poll a condition with a deadline.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { spawnSync } from 'node:child_process';
import { startVehicle, launchBrowser, openPage, telemetry, takeControlAndArm, until, withVehicle, boardKeptPace } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

const inside = (box, vp) => box && box.x >= 0 && box.y >= 0 && box.x + box.width <= vp.width + 0.5 && box.y + box.height <= vp.height + 0.5;

for (const vp of [{ width: 1366, height: 768 }, { width: 1024, height: 768 }, { width: 768, height: 1024 }]) {
  test(`${vp.width}x${vp.height}: video ≥ 55 % of the screen; arm, control, mode and STOP visible without scrolling`, () => withVehicle(async (v) => {
    const { page, context, problems } = await openPage(browser, v.url, vp);
    await until(() => page.evaluate(() => window.neptunus.video.frames > 0), 15000, 'a video frame');
    const cover = await page.evaluate(() => {
      const r = document.getElementById('video-box').getBoundingClientRect();
      return (r.width * r.height) / (innerWidth * innerHeight);
    });
    assert.ok(cover >= 0.55, `the video covers ${(cover * 100).toFixed(1)} % of ${vp.width}x${vp.height}`);
    assert.equal(await page.evaluate(() => scrollY), 0);
    for (const sel of ['[data-testid=arm]', '[data-testid=disarm]', '[data-testid=request-control]',
      'input[name=mode][value="19"]', 'input[name=mode][value="2"]', '[data-testid=surface]', '[data-testid=state]',
      '[data-testid=battery]']) {
      const el = page.locator(sel).first();
      assert.ok(await el.isVisible(), `${sel} visible`);
      assert.ok(inside(await el.boundingBox(), vp), `${sel} inside the ${vp.width}x${vp.height} viewport: ${JSON.stringify(await el.boundingBox())}`);
    }
    assert.match(await page.textContent('[data-testid=disarm]'), /STOP/);
    // The developer view opens where it can be seen.
    await page.click('[data-testid=dev-toggle]');
    await until(async () => inside(await page.locator('[data-testid=add-plot]').boundingBox(), vp)
      && inside(await page.locator('[data-testid=signal]').boundingBox(), vp), 5000, 'the developer view scrolled into sight');
    assert.deepEqual(problems, []);
    await context.close();
  }));
}

test('the HUD shows the vehicle\'s armed state, mode and battery in the page\'s words', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  const t = await until(async () => { const x = await telemetry(page); return x.voltage_v != null && x.battery_pct != null && x; }, 10000, 'battery telemetry');
  const battery = await page.textContent('[data-testid=battery]');
  assert.ok(battery.includes(`${t.voltage_v.toFixed(1)} V`), battery);
  assert.ok(battery.includes(`${t.battery_pct} %`), battery);
  assert.match(await page.textContent('[data-testid=armed-state]'), /^DISARMED$/);
  // Arm offers only what the vehicle would do: not before control is taken.
  assert.equal(await page.isDisabled('[data-testid=arm]'), true);
  assert.match(await page.getAttribute('[data-testid=arm]', 'title'), /Request control first/);
  // One vocabulary: the HUD names the mode as the mode buttons do.
  const label = await page.locator('input[name=mode]:checked').evaluate((r) => r.parentElement.textContent.trim());
  assert.equal((await page.textContent('[data-testid=mode-name]')).trim(), label);
  await takeControlAndArm(page);
  await until(async () => (await page.textContent('[data-testid=armed-state]')) === 'ARMED', 5000, 'ARMED on the HUD');
  assert.equal(await page.getAttribute('[data-testid=state]', 'class'), 'armed');
  // Armed, the Arm button says so and cannot be pressed again; STOP disarms.
  await until(async () => (await page.textContent('[data-testid=arm]')) === 'Armed', 5000, 'Arm reading "Armed"');
  assert.equal(await page.isDisabled('[data-testid=arm]'), true);
  await page.check('input[name=mode][value="0"]');
  await until(async () => (await page.textContent('[data-testid=mode-name]')).trim() === 'Heading hold', 10000, 'the new mode on the HUD');
  // STOP disarms.
  await page.click('[data-testid=disarm]');
  await until(async () => !(await telemetry(page)).armed, 5000, 'disarmed by STOP');
  await until(async () => !(await page.isDisabled('[data-testid=arm]')), 5000, 'Arm pressable again after STOP');
  assert.equal(await page.textContent('[data-testid=arm]'), 'Arm');
  await context.close();
}));

test('Space and Enter cannot accept a control request; the prompt neither scrolls the page nor takes focus', () => withVehicle(async (v) => {
  const a = await openPage(browser, v.url, { width: 768, height: 1024 });
  const b = await openPage(browser, v.url);
  try {
    await handover(a, b);
  } finally {
    await a.context.close();
    await b.context.close();
  }
}));

async function handover(a, b) {
  await takeControlAndArm(a.page);
  // A's pilot scrolled nowhere and is driving with the keyboard.
  await a.page.keyboard.down('KeyW');
  const focusBefore = await a.page.evaluate(() => document.activeElement.tagName);
  await b.page.click('[data-testid=request-control]');
  await a.page.waitForSelector('[data-testid=request-dialog]:not([hidden])', { timeout: 10000 });
  assert.equal(await a.page.evaluate(() => scrollY), 0, 'the page did not scroll');
  assert.equal(await a.page.evaluate(() => document.activeElement.tagName), focusBefore, 'the focus stayed');
  const box = await a.page.locator('[data-testid=request-dialog]').boundingBox();
  assert.ok(inside(box, { width: 768, height: 1024 }), JSON.stringify(box));
  assert.match(await a.page.textContent('[data-testid=request-countdown]'), /^\d+ s$/);
  // The requester is told it waits, not that it failed.
  await until(async () => /Waiting for GCS 200 to answer/.test(await b.page.textContent('[data-testid=request-pending]')), 5000, 'the waiting note');
  assert.equal(await b.page.locator('#messages li', { hasText: 'FAILED' }).count(), 0);
  // Space and Enter, even with the focus on Accept, hand nothing over.
  await a.page.keyboard.up('KeyW');
  await a.page.keyboard.press('Space');
  await a.page.keyboard.press('Enter');
  await a.page.focus('[data-testid=accept]');
  await a.page.keyboard.press('Space');
  await a.page.keyboard.press('Enter');
  await a.page.waitForTimeout(500);
  assert.equal((await telemetry(a.page)).control.you, true, 'A still in control');
  assert.ok(await a.page.isVisible('[data-testid=request-dialog]'));
  // A click does.
  await a.page.click('[data-testid=accept]');
  await until(async () => (await telemetry(b.page)).control.you, 10000, 'B in control');
  await until(async () => await b.page.isHidden('[data-testid=request-pending]'), 5000, 'the waiting note gone');
}

test('W drives again after Enter or Escape in a setpoint field; held keys light their touch buttons', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  await takeControlAndArm(page);
  await page.click('#ap-heading');
  await page.keyboard.type('90');
  await page.keyboard.press('Enter');
  await page.keyboard.down('KeyW');
  await until(async () => (await telemetry(page)).thrusters_us?.port !== 1500, 10000, 'forward thrust after Enter');
  assert.match(await page.getAttribute('#touchpad .tp[data-key=KeyW]', 'class'), /held/);
  assert.match(await page.textContent('[data-testid=drive-indicator]'), /forward 100 %/);
  await page.keyboard.up('KeyW');
  await until(async () => (await telemetry(page)).thrusters_us?.port === 1500, 10000, 'neutral');
  await page.click('#ap-depth');
  await page.keyboard.type('1');
  await page.keyboard.press('Escape');
  await page.keyboard.down('KeyW');
  await until(async () => (await telemetry(page)).thrusters_us?.port !== 1500, 10000, 'forward thrust after Escape');
  await page.keyboard.up('KeyW');
  await context.close();
}));

test('a run-mode round trip keeps the setpoints and the vehicle at depth; the radios show the vehicle\'s run mode', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  await takeControlAndArm(page);
  // Depth hold needs a depth estimate, which the board's first depth
  // readings make a moment after the link is up (earlier, the vehicle
  // refuses the mode and says why).
  await until(async () => (await telemetry(page)).health?.depth === true, 20000, 'a depth reading');
  await page.check('input[name=mode][value="2"]');
  await until(async () => (await telemetry(page)).mode === 2, 10000, 'depth + heading hold');
  await page.fill('#ap-depth', '1.5');
  await page.fill('#ap-heading', '60');
  await page.click('#ap-form button[type=submit]');
  await until(async () => {
    const t = await telemetry(page);
    return Math.abs(t.depth_m - 1.5) < 0.15 && Math.abs(((t.heading_deg - 60 + 540) % 360) - 180) < 5;
  }, 60000, 'at 1.5 m, heading 60°');
  await page.check('input[name=run][value=simulator]');
  await until(async () => (await telemetry(page)).simulated, 10000, 'simulator run mode');
  assert.ok(await page.isChecked('input[name=run][value=simulator]'));
  await page.check('input[name=run][value=normal]');
  await until(async () => !(await telemetry(page)).simulated, 10000, 'back to the real vehicle');
  assert.ok(await page.isChecked('input[name=run][value=normal]'));
  const ap = (await telemetry(page)).autopilot;
  assert.ok(Math.abs(ap.depth_target_m - 1.5) < 1e-3, JSON.stringify(ap));
  assert.ok(Math.abs(ap.heading_target_deg - 60) < 0.5, JSON.stringify(ap));
  // In SIMULATOR run mode the real board was stopped and the ROV floated
  // up for as long as the round trip took (longer on a busy machine): back
  // in normal run mode, the kept setpoints bring it back to 1.5 m and 60°,
  // and it stays there — it neither rises nor turns north. The stay is
  // judged where the board's world kept pace (boardKeptPace), tried again
  // where it did not.
  for (let attempt = 1; ; attempt++) {
    await until(async () => {
      const t = await telemetry(page);
      return Math.abs(t.depth_m - 1.5) < 0.15 && Math.abs(((t.heading_deg - 60 + 540) % 360) - 180) < 5;
    }, 60000, 'back at 1.5 m, heading 60°');
    const mark = v.stderr().length;
    let shallowest = Infinity;
    const end = Date.now() + 8000;
    while (Date.now() < end) {
      shallowest = Math.min(shallowest, (await telemetry(page)).depth_m);
      await page.waitForTimeout(250);
    }
    const pace = await boardKeptPace(v, mark);
    if (pace.kept) {
      assert.ok(shallowest > 1.2, `rose to ${shallowest} m (${pace.why})`);
      console.log(`stay judged (${pace.why}): shallowest ${shallowest} m`);
      break;
    }
    console.log(`stay not judged: the board's world did not keep pace (${pace.why}); shallowest ${shallowest} m`);
    if (attempt === 4) {
      console.log('THE STAY WAS NOT JUDGED: in 4 tries the machine never let the board\'s world keep pace');
      break;
    }
  }
  await context.close();
}));

/** An MJPEG camera the test can pause: frames every 100 ms while running. */
async function pausableCamera() {
  // A real JPEG from ffmpeg (installed for the camera tests).
  const r = spawnSync('ffmpeg', ['-hide_banner', '-loglevel', 'error', '-f', 'lavfi', '-i', 'testsrc=size=160x120:rate=1',
    '-frames:v', '1', '-f', 'mjpeg', '-'], { maxBuffer: 1 << 20 });
  if (r.status !== 0) throw new Error(`ffmpeg: ${r.stderr}`);
  const jpeg = r.stdout;
  const state = { running: true, clients: new Set() };
  const server = createServer((req, res) => {
    res.writeHead(200, { 'Content-Type': 'multipart/x-mixed-replace; boundary=cam' });
    state.clients.add(res);
    req.on('close', () => state.clients.delete(res));
  });
  const timer = setInterval(() => {
    if (!state.running) return;
    for (const res of state.clients) {
      res.write(`--cam\r\nContent-Type: image/jpeg\r\nContent-Length: ${jpeg.length}\r\n\r\n`);
      res.write(jpeg);
      res.write('\r\n');
    }
  }, 100);
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  return {
    url: `http://127.0.0.1:${server.address().port}/stream`,
    pause() { state.running = false; },
    resume() { state.running = true; },
    close() { clearInterval(timer); for (const c of state.clients) c.destroy(); server.close(); },
  };
}

test('a stalled camera shows VIDEO LOST within 1.5 s, and the picture comes back by itself', async () => {
  const cam = await pausableCamera();
  try {
    await withVehicle(async (v) => {
      const { page, context } = await openPage(browser, v.url);
      await until(() => page.evaluate(() => window.neptunus.video.frames > 2), 15000, 'frames from the camera');
      assert.ok(await page.isHidden('[data-testid=video-lost]'));
      // The page's rule: the overlay once the last frame is older than
      // VIDEO_LOST_MS. How soon a busy machine lets this test see it is not
      // the page's doing: the wait is generous, the rule read from the page.
      const lostMs = await page.evaluate(async () => (await import('/js/view.js')).VIDEO_LOST_MS);
      assert.ok(lostMs <= 1500, `VIDEO_LOST_MS ${lostMs}`);
      cam.pause();
      await until(() => page.isVisible('[data-testid=video-lost]'), 15000, 'the VIDEO LOST overlay');
      const age = await page.evaluate(() => window.neptunus.video.frameAgeMs(performance.now()));
      assert.ok(age > lostMs, `VIDEO LOST shown with the last frame ${age} ms old`);
      assert.match(await page.textContent('[data-testid=video-lost]'), /VIDEO LOST — last frame \d+ s ago/);
      cam.resume();
      await until(() => page.isHidden('[data-testid=video-lost]'), 20000, 'the picture back');
      await context.close();
    }, [], { toml: `[camera]\nsource = "url"\nurl = "${cam.url}"\nstall_timeout_s = 1.0\n` });
  } finally {
    cam.close();
  }
});

test('after the vehicle process restarts, video and telemetry return without a reload', async () => {
  const first = await startVehicle();
  const { page, context } = await openPage(browser, first.url);
  const addr = new URL(first.url).host;
  await until(() => page.evaluate(() => window.neptunus.video.frames > 2), 15000, 'frames');
  await first.stop();
  await until(() => page.isVisible('[data-testid=disconnected]'), 5000, 'the DISCONNECTED state');
  await until(() => page.isVisible('[data-testid=video-lost]'), 5000, 'the picture marked lost');
  assert.match(await page.textContent('[data-testid=conn]'), /disconnected/);
  const second = await startVehicle([], { http: addr });
  try {
    const framesBefore = await page.evaluate(() => window.neptunus.video.frames);
    await until(() => page.isHidden('[data-testid=disconnected]'), 15000, 'reconnected');
    await until(async () => (await telemetry(page))?.vehicle_seen, 15000, 'telemetry again');
    await until(() => page.evaluate((n) => window.neptunus.video.frames > n + 2, framesBefore), 15000, 'new frames');
    await until(() => page.isHidden('[data-testid=video-lost]'), 5000, 'the picture live again');
  } finally {
    await context.close();
    await second.stop();
  }
});

test('a failsafe shows its reason on the HUD and in the alerts, also to a pilot who joins late, and is spoken when asked', () => withVehicle(async (v) => {
  const a = await openPage(browser, v.url);
  const b = await openPage(browser, v.url);
  try {
    // B's pilot asked for spoken alerts; the test listens to what would be said.
    await b.page.evaluate(() => {
      window.spoken = [];
      window.speechSynthesis.speak = (u) => window.spoken.push(u.text);
    });
    await b.page.check('[data-testid=speak]');
    await takeControlAndArm(a.page);
    // A's pilot walks away: the tab closes, the owner's heartbeat stops.
    await a.context.close();
    await until(() => b.page.isVisible('[data-testid=fs-banner]'), 20000, 'the failsafe banner');
    const banner = await b.page.textContent('[data-testid=fs-banner]');
    assert.match(banner, /^FAILSAFE: .*(heartbeat|pilot input|manual control)/i, banner);
    await until(() => b.page.locator('#messages li').filter({ hasText: /Failsafe: / }).count(), 10000, 'the failsafe alert');
    const alert = await b.page.locator('#messages li').filter({ hasText: /Failsafe: / }).first().getAttribute('data-severity');
    assert.ok(['WARNING', 'CRITICAL', 'ERROR', 'ALERT', 'EMERGENCY'].includes(alert), alert);
    await until(() => b.page.evaluate(() => window.spoken.some((s) => /failsafe/i.test(s))), 5000, 'the failsafe spoken');
    assert.ok(await b.page.isVisible('[data-testid=alert-badge]'));
    // A pilot who opens the page now sees the reason without having seen the text.
    const c = await openPage(browser, v.url);
    await until(() => c.page.isVisible('[data-testid=fs-banner]'), 10000, 'the banner for a late joiner');
    assert.doesNotMatch(await c.page.textContent('[data-testid=fs-banner]'), /vehicle critical$/);
    await c.context.close();
  } finally {
    await a.context.close().catch(() => {});
    await b.context.close();
  }
}));

test('a vehicle that hangs with its socket open: the HUD turns stale (data older than 2 s at most) and live again when it resumes', () => withVehicle(async (v) => {
  const { page, context } = await openPage(browser, v.url);
  await until(async () => !(await page.getAttribute('[data-testid=state]', 'class')).includes('stale')
    && !(await page.getAttribute('[data-testid=battery]', 'class')).includes('stale'), 10000, 'live HUD');
  // A picture must be showing before it can be lost (on a busy machine the
  // first frame can come after the HUD is live).
  await until(() => page.evaluate(() => window.neptunus.video.frames > 0), 15000, 'a video frame');
  const stale = () => page.evaluate(() => ({
    state: document.querySelector('[data-testid=state]').classList.contains('stale'),
    battery: document.querySelector('[data-testid=battery]').classList.contains('stale'),
    attitudeAge: window.neptunus.view.ageOf('attitude'),
  }));
  // What turns the HUD stale is the page's own rule (data older than its
  // STALE_MS, checked every frame); how soon a busy machine lets this test
  // see it is not the page's doing, so the wait is generous and the rule is
  // read from the page.
  const staleMs = await page.evaluate(async () => (await import('/js/hud.js')).STALE_MS);
  assert.ok(staleMs <= 2000, `STALE_MS ${staleMs}`);
  process.kill(v.pid, 'SIGSTOP');
  try {
    await until(async () => { const s = await stale(); return s.state && s.battery && s.attitudeAge > staleMs; }, 15000, 'the HUD marked stale');
    // The socket is still open: not DISCONNECTED, but the picture is lost too.
    await until(() => page.isVisible('[data-testid=video-lost]'), 15000, 'the picture marked lost');
  } finally {
    process.kill(v.pid, 'SIGCONT');
  }
  await until(async () => { const s = await stale(); return !s.state && !s.battery && s.attitudeAge < 1000; }, 10000, 'the HUD live again');
  await until(() => page.isHidden('[data-testid=video-lost]'), 10000, 'the picture back');
  await context.close();
}));

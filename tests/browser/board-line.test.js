// The board pill tells the pilot how the serial line to the board fares:
// "board: link up" on a clean line, "… · line X % damaged" beside it when
// frames or lines are damaged or lost, amber from 1 %. The damage is real:
// the board emulator behind the vehicle's pseudo-terminal tears some of
// its telemetry lines ([emulator.faults], seeded), the vehicle's link
// rejects them, SYS_STATUS carries the share, and the page shows it. The
// pill is read at laptop and tablet sizes; their screenshots go to
// target/browser-screenshots/ for a person to look at.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { launchBrowser, openPage, telemetry, until, withVehicle, REPO } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

const shots = join(REPO, 'target', 'browser-screenshots');
mkdirSync(shots, { recursive: true });

// One telemetry line in eight torn on its way to the vehicle.
const DAMAGING = '[emulator.faults]\ntorn = 0.125\nseed = 37\n';
const DAMAGED = /^board: link up · line (\d+(?:\.\d)?) % damaged$/;

/** The pill's text, class and tooltip, whether it shows all of its text
 * inside the viewport, and the telemetry it was drawn from — one snapshot,
 * taken at once (telemetry comes several times a second). */
async function pill(page, vp) {
  const p = await page.evaluate(() => {
    const e = document.querySelector('[data-testid=link]');
    const r = e.getBoundingClientRect();
    return {
      text: e.textContent.trim(),
      cls: e.className,
      title: e.title,
      clipped: e.scrollWidth > e.clientWidth + 0.5,
      box: { x: r.x, y: r.y, width: r.width, height: r.height },
      health: window.neptunus.state.t?.health,
    };
  });
  const b = p.box;
  p.inside = b.x >= 0 && b.y >= 0 && b.x + b.width <= vp.width + 0.5 && b.y + b.height <= vp.height + 0.5;
  return p;
}

test('a damaged line shows on the board pill, amber, readable at laptop and tablet sizes', () => withVehicle(async (v) => {
  for (const vp of [{ width: 1366, height: 768 }, { width: 1024, height: 768 }, { width: 768, height: 1024 }]) {
    const { page, context, problems } = await openPage(browser, v.url, vp);
    // The link's share over its 10-s window, from SYS_STATUS drop_rate_comm.
    const t = await until(async () => {
      const x = await telemetry(page);
      return x.health?.board_link && x.health.board_line_drop_pct >= 1 && x;
    }, 30000, 'the vehicle reporting a damaged board line');
    assert.ok(t.health.board_line_errors > 0, JSON.stringify(t.health));
    const p = await until(async () => {
      const x = await pill(page, vp);
      return DAMAGED.test(x.text) && Number(DAMAGED.exec(x.text)[1]) >= 1 && x;
    }, 10000, 'the pill saying the line is damaged');
    const shown = Number(DAMAGED.exec(p.text)[1]);
    assert.ok(shown >= 1 && shown < 50, `${p.text}: torn lines are one in eight`);
    assert.match(p.cls, /\bwarn\b/, `amber from 1 %: ${p.cls}`);
    assert.match(p.title, /board serial line: [\d.]+ % of frames and lines damaged or lost over the last 10 s, \d+ since the start/);
    assert.ok(p.inside, `the pill inside ${vp.width}x${vp.height}: ${JSON.stringify(p.box)}`);
    assert.equal(p.clipped, false, `the pill's text cut at ${vp.width}x${vp.height}`);
    // The bar does not push the page wider than the screen; where the
    // longer pill wraps it onto a second row (768 wide), the video keeps
    // the share of the screen the pilot's tests ask of it.
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - innerWidth);
    assert.ok(overflow <= 0, `horizontal overflow of ${overflow} px at ${vp.width}x${vp.height}`);
    const cover = await page.evaluate(() => {
      const r = document.getElementById('video-box').getBoundingClientRect();
      return (r.width * r.height) / (innerWidth * innerHeight);
    });
    assert.ok(cover >= 0.55, `the video covers ${(cover * 100).toFixed(1)} % of ${vp.width}x${vp.height}`);
    // Dark text on the amber pill (the light text read at 2.9:1).
    assert.equal(await page.locator('[data-testid=link]').evaluate((e) => getComputedStyle(e).color), 'rgb(17, 17, 17)');
    await page.screenshot({ path: join(shots, `board-line-damaged-${vp.width}x${vp.height}.png`) });
    await page.locator('#bar').screenshot({ path: join(shots, `board-line-damaged-bar-${vp.width}x${vp.height}.png`) });
    assert.deepEqual(problems, []);
    await context.close();
  }
}, [], { toml: DAMAGING }));

test('a clean line shows only "link up", green, and no share', () => withVehicle(async (v) => {
  const vp = { width: 1366, height: 768 };
  const { page, context, problems } = await openPage(browser, v.url, vp);
  // Once the link's 10-s window holds nothing damaged or lost (on a busy
  // machine an echo can come too late to count, for a while).
  const p = await until(async () => {
    const x = await pill(page, vp);
    return x.health?.board_link && x.health.board_line_drop_pct === 0 && x;
  }, 60000, 'a clean board line');
  assert.equal(p.text, 'board: link up');
  assert.match(p.cls, /\bok\b/);
  assert.match(p.title, /board serial line: 0\.00 % of frames and lines damaged or lost/);
  await page.locator('#bar').screenshot({ path: join(shots, `board-line-clean-bar-${vp.width}x${vp.height}.png`) });
  assert.deepEqual(problems, []);
  await context.close();
}));

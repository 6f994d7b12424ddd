// Takes the user guide's screenshots of the operator interface (laptop
// 1366×768, tablet 768×1024) and the developer interface
// (docs/guide/src/screenshots/*.png, which the README shows too)
// from the real binary in --sim:
//   cargo build && (cd tests/browser && npm ci && node screenshots.js)
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { startVehicle, launchBrowser, openPage, takeControlAndArm, until, telemetry, REPO } from './harness.js';

const out = join(REPO, 'docs', 'guide', 'src', 'screenshots');
mkdirSync(out, { recursive: true });
const v = await startVehicle();
const browser = await launchBrowser();
try {
  // The tablet in portrait first, watching (nobody in control yet).
  const tablet = await openPage(browser, v.url, { width: 768, height: 1024 });
  await tablet.page.waitForTimeout(1500);
  await tablet.page.screenshot({ path: join(out, 'operator-tablet.png') });
  await tablet.context.close();
  const { page } = await openPage(browser, v.url, { width: 1366, height: 768 });
  await takeControlAndArm(page);
  // Drive forward and turn for a while so the readouts and plots have something to show.
  await page.keyboard.down('KeyW');
  await page.keyboard.down('KeyD');
  await until(async () => (await telemetry(page)).sim?.surge_mps > 0.2, 20000, 'the ROV moving');
  await page.waitForTimeout(3000);
  await page.keyboard.up('KeyD');
  await page.waitForTimeout(1500);
  await page.screenshot({ path: join(out, 'operator.png') });
  await page.click('[data-testid=dev-toggle]');
  for (const s of ['sim_u_mps', 'sim_psi_deg', 'starboard_us', 'cmd_yaw']) {
    await page.selectOption('#signal', s);
    await page.click('[data-testid=add-plot]');
  }
  await page.waitForTimeout(1500);
  await page.keyboard.up('KeyW');
  await page.waitForTimeout(800);
  await page.locator('#dev').screenshot({ path: join(out, 'developer.png') });
  process.stdout.write(`screenshots in ${out}\n`);
} finally {
  await browser.close();
  await v.stop();
}

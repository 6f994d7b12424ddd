import { launchBrowser, startVehicle, openPage, takeControlAndArm, until, telemetry } from './harness.js';
const v = await startVehicle();
const browser = await launchBrowser();
try {
  for (const vp of [{ width: 1366, height: 768 }, { width: 1024, height: 768 }, { width: 768, height: 1024 }]) {
    const { page, context, problems } = await openPage(browser, v.url, vp);
    if (vp.width === 1366) {
      await takeControlAndArm(page);
      await page.keyboard.down('KeyW');
      await page.keyboard.down('KeyQ');
      await page.waitForTimeout(2500);
    } else {
      await page.waitForTimeout(1500);
    }
    const cover = await page.evaluate(() => { const r = document.getElementById('video-box').getBoundingClientRect(); return (r.width * r.height) / (innerWidth * innerHeight); });
    await page.screenshot({ path: `/tmp/shots/op-${vp.width}x${vp.height}.png` });
    console.log(vp, 'video cover', cover.toFixed(3), problems);
    if (vp.width === 1366) { await page.keyboard.up('KeyW'); await page.keyboard.up('KeyQ'); }
    await context.close();
  }
} finally { await browser.close(); await v.stop(); }

// The server's page in a real browser (ctest serve_browser): Debian's Chromium, headless, driven
// by puppeteer-core, with the bundled recording played as its microphone
// (--use-file-for-fake-audio-capture).
//   Record: the page opened with ?autostart=1 streams the microphone to the server; the live
//     impacts' intervals equal those `bouncecal detect` finds in the same file (times differ by
//     where the capture started) for at least 95 % of the impacts; after Stop the page shows the
//     take's analysis; a screenshot is not blank and shows the red impact marks.
//   File: the recording uploaded through the file input gives exactly `analyze --json`; the
//     scene form calibrates it.
//   Nothing is loaded from the network.
//
//   node tests/browser/serve_browser.mjs --bouncecal build/bouncecal
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { arg, compareIntervals, launch, recordRequests, scratch, startServer, takeIsTheFile, toWav } from './harness.mjs';

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const bouncecal = path.resolve(arg('bouncecal', path.join(root, 'build/bouncecal')));
const flac = path.join(root, 'data/default_steel_copper.flac');

function cli(args, cwd) {
  return JSON.parse(execFileSync(bouncecal, args, { cwd, maxBuffer: 1 << 26 }).toString());
}

// Red (#d62728) pixels of a PNG screenshot, counted by the page itself (a data: URL into a
// canvas), with the share of pixels that are not white.
async function screenshotPixels(page, clip) {
  const png = await page.screenshot({ encoding: 'base64', clip });
  return page.evaluate(async (data) => {
    const img = new Image();
    img.src = 'data:image/png;base64,' + data;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width; c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const px = g.getImageData(0, 0, c.width, c.height).data;
    let red = 0, ink = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (Math.abs(px[i] - 0xd6) < 30 && Math.abs(px[i + 1] - 0x27) < 30 && Math.abs(px[i + 2] - 0x28) < 30) red++;
      if (px[i] < 245 || px[i + 1] < 245 || px[i + 2] < 245) ink++;
    }
    return { red, ink, total: px.length / 4 };
  }, png);
}

// One take: false when the browser dropped captured audio (the take is not the file), so that
// the comparison with the file means nothing.
async function recordTest(server, dir, attempt) {
  const wav = toWav(flac, dir);
  const browser = await launch(path.join(dir, 'profile-record-' + attempt), wav);
  try {
    const page = await browser.newPage();
    const foreign = recordRequests(page, server.url);
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    await page.goto(server.url + '?autostart=1');
    await page.waitForFunction(() => document.body.dataset.state === 'recording', { timeout: 20000 });
    // The file plays once (1 s of silence, the 9.2 s recording): stop a second after it.
    await page.waitForFunction(() => window.bouncecal.captured_s >= 11.2, { timeout: 60000, polling: 200 });
    await page.click('#stop');
    await page.waitForFunction(() => ['ready', 'error'].includes(document.body.dataset.state), { timeout: 60000 });
    const state = await page.evaluate(() => ({
      status: document.getElementById('status').textContent,
      live: Array.from(window.bouncecal.live.values()),
      latencies: window.bouncecal.latencies,
      analysis: window.bouncecal.analysis,
      marks: Number(document.getElementById('wave').dataset.marks),
      take: window.bouncecal.take,
    }));
    assert.equal(errors.length, 0, errors.join('\n'));
    const takeFile = path.join(dir, 'take.flac');
    fs.writeFileSync(takeFile, Buffer.from(await (await fetch(new URL(state.take.url, server.url))).arrayBuffer()));
    const intact = takeIsTheFile(takeFile, wav);
    if (!intact.exact) {
      console.log(`record: the browser dropped captured audio (the take differs from the file: ${JSON.stringify(intact)}): taken again`);
      return false;
    }
    assert.ok(state.analysis, state.status);
    const detect = cli(['detect', wav, '--json']);
    const main = detect.sequences[detect.chosen_sequences[0]].impacts;  // the main sequence's
    // The live session's longest sequence against detect's main sequence.
    const bySeq = new Map();
    for (const i of state.live) bySeq.set(i.sequence, [...(bySeq.get(i.sequence) || []), i]);
    const live = [...bySeq.values()].sort((a, b) => b.length - a.length)[0].sort((a, b) => a.index - b.index);
    // Agreement within 3 sigmas and a quarter sample: a window re-times an impact by a fraction of
    // a sample that sigma leaves out (LiveOptions::revise_floor_samples), plus the take's rounding.
    const cmp = compareIntervals(live, main, 1e-6 + 0.25 / detect.sample_rate_hz);
    console.log(`record: ${live.length} live impacts, ${main.length} by detect, offset ${cmp.offset_s.toFixed(4)} s, ` +
      `${(100 * cmp.reproduced).toFixed(1)} % of the intervals reproduced; the take's analysis: ` +
      `${state.analysis.bounces.length} impacts; latency median ` +
      `${state.latencies.sort((a, b) => a - b)[state.latencies.length >> 1].toFixed(0)} ms`);
    assert.ok(cmp.reproduced >= 0.95, `only ${(100 * cmp.reproduced).toFixed(1)} % of the intervals reproduced`);
    // The take's analysis is the batch detector's on the take: what `analyze` prints for it.
    const analyzed = cli(['analyze', takeFile, '--json']);
    analyzed.file = state.analysis.file;
    assert.deepEqual(state.analysis, analyzed);
    assert.equal(state.marks, state.analysis.bounces.length);
    const wave = await page.$('#wave');
    const shot = await screenshotPixels(page, await wave.boundingBox());
    console.log(`screenshot of the waveform: ${shot.red} red pixels, ${(100 * shot.ink / shot.total).toFixed(1)} % not white`);
    assert.ok(shot.ink > shot.total / 50, 'the screenshot is blank');
    assert.ok(shot.red > state.marks * 20, 'the impact marks are not on the screenshot');
    assert.deepEqual(foreign, [], 'requests outside the server: ' + foreign.join(', '));
    // The take is downloadable from the page, as FLAC.
    const take = await page.evaluate(async (url) => {
      const r = await fetch(url);
      const b = new Uint8Array(await r.arrayBuffer());
      return { status: r.status, type: r.headers.get('content-type'), magic: String.fromCharCode(...b.slice(0, 4)) };
    }, state.take.url);
    assert.deepEqual(take, { status: 200, type: 'audio/flac', magic: 'fLaC' });
    return true;
  } finally {
    await browser.close();
  }
}

async function uploadTest(server, dir) {
  const browser = await launch(path.join(dir, 'profile-file'));
  try {
    const page = await browser.newPage();
    const foreign = recordRequests(page, server.url);
    await page.goto(server.url);
    const input = await page.$('#file-input');
    await input.uploadFile(flac);
    await page.waitForFunction(() => ['ready', 'error'].includes(document.body.dataset.state), { timeout: 60000 });
    const analysis = await page.evaluate(() => window.bouncecal.analysis);
    assert.ok(analysis, await page.evaluate(() => document.getElementById('status').textContent));
    // The CLI run where the file is, so that "file" is the same name.
    assert.deepEqual(analysis, cli(['analyze', path.basename(flac), '--json'], path.dirname(flac)));
    await page.type('input[name=height]', '0.2');
    await page.type('input[name=diameter]', '0.01');
    await page.type('input[name=material]', 'steel');
    // The recording's impacts include each contact (data/default_steel_copper.toml).
    await page.click('input[name=contact_duration]');
    await page.waitForFunction(() => document.querySelectorAll('#law option').length > 3);
    await page.select('#law', 'hertz-viscoelastic');
    await page.click('#calibrate');
    await page.waitForFunction(() => ['calibrated', 'error'].includes(document.body.dataset.state), { timeout: 120000 });
    const params = await page.evaluate(() => window.bouncecal.params);
    assert.ok(params, await page.evaluate(() => document.getElementById('status').textContent));
    assert.equal(params.fit.outcome, 'converged');
    const evPoints = await page.evaluate(() => Number(document.getElementById('ev').dataset.points));
    assert.ok(evPoints >= 60, 'the e(v) plot has the bounces');
    console.log(`upload: analysis equals analyze --json (${analysis.bounces.length} bounces); calibrated ${params.law.name}: ${params.fit.outcome}`);
    assert.deepEqual(foreign, [], 'requests outside the server: ' + foreign.join(', '));
  } finally {
    await browser.close();
  }
}

const dir = scratch('bc-browser');
const server = await startServer(bouncecal);
let failed = false;
try {
  let recorded = false;
  for (let attempt = 0; attempt < 3 && !recorded; attempt++) recorded = await recordTest(server, dir, attempt);
  assert.ok(recorded, 'the browser dropped captured audio in three takes (is the machine overloaded?)');
  await uploadTest(server, dir);
} catch (e) {
  failed = true;
  console.error(e.stack || String(e));
  console.error('server stderr:\n' + server.stderr());
} finally {
  const code = await server.stop();
  fs.rmSync(dir, { recursive: true, force: true });
  if (code !== 0) { console.error('the server exited with ' + code); failed = true; }
}
process.exit(failed ? 1 : 0);

// bench_live.mjs — the live path end to end (`bouncecal serve`, its page, Debian's Chromium):
//
//   node tools/bench_live.mjs                      # latency and CPU, then a 10-minute stream
//   node tools/bench_live.mjs --minutes 60 --takes 3 --bouncecal build/bouncecal
//
// Latency and CPU: Chromium plays the bundled recording (three drops in a row, ~28 s) as its
// fake microphone into the page opened with ?autostart=1 (the page streams it to the server);
// for each impact the page notes when its message arrived against the impact's time in the take
// plus the moment the take's first sample reached the page (window.bouncecal.latencies): that
// leaves out the fake device's own buffering (tens of ms), and includes the page's 2048-sample
// frames, the network, the server's settle time and detection. The server's CPU time (user +
// system, /proc/PID/stat) over the take, per second of it, is the share of one core a live take
// takes at the device's rate (44.1 kHz, the fake device's). A take in which the browser dropped
// audio (not the file's samples) is reported and not counted.
// Memory: the page's WebSocket streams --minutes of 48 kHz audio (the recording and 20 s of
// room noise in turn) as fast as the server takes it; the server's resident memory (VmRSS) is
// read as it goes, and its CPU time per second of audio is the real-time share at 48 kHz. Then
// the stop: the whole take's analysis (the batch detector on the hour), its time and the peak
// (VmHWM). Prints Markdown tables.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { arg, launch, processStats, scratch, startServer, takeIsTheFile } from '../tests/browser/harness.mjs';
import { execFileSync } from 'node:child_process';

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
const bouncecal = path.resolve(arg('bouncecal', path.join(root, 'build/bouncecal')));
const minutes = Number(arg('minutes', '10'));
const takes = Number(arg('takes', '3'));
const flac = path.join(root, 'data/default_steel_copper.flac');

function quantile(v, p) {
  const s = [...v].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor(p * s.length))];
}

// Three drops in a row at 44.1 kHz, with silence before and after (tests/browser/harness.mjs
// toWav says why).
function threeDrops(dir) {
  const out = path.join(dir, 'three.wav');
  execFileSync('ffmpeg', ['-loglevel', 'error', '-y', '-stream_loop', '2', '-i', flac, '-ar', '44100',
    '-af', 'adelay=1000:all=1,apad=pad_dur=3', '-c:a', 'pcm_s16le', out]);
  return out;
}

async function latencyTake(server, dir, wav, n) {
  const browser = await launch(path.join(dir, 'profile-' + n), wav);
  try {
    const page = await browser.newPage();
    await page.goto(server.url + '?autostart=1');
    await page.waitForFunction(() => document.body.dataset.state === 'recording', { timeout: 20000 });
    const before = processStats(server.pid);
    await page.waitForFunction(() => window.bouncecal.captured_s >= 29.5, { timeout: 90000, polling: 250 });
    const after = processStats(server.pid);
    const captured = await page.evaluate(() => window.bouncecal.captured_s);
    await page.click('#stop');
    await page.waitForFunction(() => ['ready', 'error'].includes(document.body.dataset.state), { timeout: 60000 });
    const st = await page.evaluate(() => ({ lat: window.bouncecal.latencies, take: window.bouncecal.take }));
    const takeFile = path.join(dir, 'take.flac');
    fs.writeFileSync(takeFile, Buffer.from(await (await fetch(new URL(st.take.url, server.url))).arrayBuffer()));
    const intact = takeIsTheFile(takeFile, wav).exact;
    return { lat: st.lat, cpu: (after.cpu - before.cpu) / captured, intact, captured };
  } finally {
    await browser.close();
  }
}

// Streams `minutes` of 48 kHz audio from the page as fast as the server takes it.
async function longStream(server, dir, samples) {
  const browser = await launch(path.join(dir, 'profile-long'));
  try {
    const page = await browser.newPage();
    await page.goto(server.url);
    const rss = [];
    const start = processStats(server.pid);
    const t0 = Date.now();
    let done = false;
    const poll = (async () => {
      while (!done) {
        const s = processStats(server.pid);
        const fed = await page.evaluate(() => window.benchFed || 0).catch(() => 0);
        rss.push({ fed_s: fed, rss: s.rss, cpu: s.cpu - start.cpu });
        await new Promise((r) => setTimeout(r, 1000));
      }
    })();
    const result = await page.evaluate(async (drop, total_s) => {
      const rate = 48000;
      const ws = new WebSocket(location.protocol.replace('http', 'ws') + '//' + location.host + '/api/live');
      ws.binaryType = 'arraybuffer';
      const messages = [];
      let analysis = null;
      const closed = new Promise((resolve) => { ws.onclose = resolve; });
      ws.onmessage = (m) => {
        const j = JSON.parse(m.data);
        if (j.type === 'analysis') analysis = j; else messages.push(j.type);
      };
      await new Promise((resolve) => { ws.onopen = resolve; });
      ws.send(JSON.stringify({ rate }));
      const x = Float32Array.from(drop);
      const gap = new Float32Array(20 * rate);
      for (let i = 0; i < gap.length; i++) gap[i] = 3e-4 * (Math.random() + Math.random() + Math.random() - 1.5) * 2;
      let fed = 0;
      window.benchFed = 0;
      while (fed < total_s * rate) {
        for (const part of [x, gap]) {
          for (let at = 0; at < part.length; at += 4096) {
            while (ws.bufferedAmount > (1 << 20)) await new Promise((r) => setTimeout(r, 5));
            ws.send(part.slice(at, at + 4096).buffer);
            fed += Math.min(4096, part.length - at);
          }
          window.benchFed = fed / rate;
        }
      }
      const stopAt = performance.now();
      ws.send(JSON.stringify({ stop: true }));
      await closed;
      return { fed_s: fed / rate, impacts: messages.filter((t) => t === 'impact').length,
        revised: messages.filter((t) => t === 'revised').length,
        analysis_s: (performance.now() - stopAt) / 1000,
        take_impacts: analysis && analysis.analysis ? analysis.analysis.bounces.length : null,
        drops: Math.ceil(fed / rate / (x.length / rate + 20)) };
    }, samples, minutes * 60);
    done = true;
    await poll;
    const end = processStats(server.pid);
    return { ...result, rss, hwm: end.hwm, wall_s: (Date.now() - t0) / 1000 };
  } finally {
    await browser.close();
  }
}

const dir = scratch('bc-bench-live');
const server = await startServer(bouncecal);
try {
  const wav = threeDrops(dir);
  const rows = [];
  for (let n = 0; n < takes; n++) rows.push(await latencyTake(server, dir, wav, n));
  const good = rows.filter((r) => r.intact);
  const lat = good.flatMap((r) => r.lat);
  console.log(`machine: ${os.cpus().length} cores, load average ${os.loadavg().map((v) => v.toFixed(1)).join(' ')}`);
  console.log('\n| takes (intact / run) | impacts | latency median | p90 | max | server CPU per s of take (44.1 kHz) |');
  console.log('|---|---|---|---|---|---|');
  console.log(`| ${good.length} / ${rows.length} | ${lat.length} | ${quantile(lat, 0.5).toFixed(0)} ms | ` +
    `${quantile(lat, 0.9).toFixed(0)} ms | ${Math.max(...lat).toFixed(0)} ms | ` +
    `${good.map((r) => (100 * r.cpu).toFixed(1) + ' %').join(', ')} |`);
  const drop = Array.from(new Float32Array(execFileSync('ffmpeg', ['-loglevel', 'error', '-i', flac, '-f', 'f32le', '-'],
    { maxBuffer: 1 << 26 }).buffer.slice(0)));
  const long = await longStream(server, dir, drop);
  const at = (s) => long.rss.filter((r) => r.fed_s <= s).map((r) => r.rss);
  const peakUpTo = (s) => (at(s).length ? Math.max(...at(s)) : NaN).toFixed(0);
  const streamCpu = long.rss.length ? long.rss[long.rss.length - 1].cpu / long.rss[long.rss.length - 1].fed_s : NaN;
  console.log(`\n| stream (48 kHz) | drops | impacts reported | revisions | RSS peak ≤ 1 min | ≤ 10 min | whole stream | CPU per s of audio | stop → analysis | peak with the analysis (VmHWM) | take's analysis |`);
  console.log('|---|---|---|---|---|---|---|---|---|---|---|');
  console.log(`| ${(long.fed_s / 60).toFixed(1)} min | ${long.drops} | ${long.impacts} | ${long.revised} | ` +
    `${peakUpTo(60)} MB | ${peakUpTo(600)} MB | ${peakUpTo(1e9)} MB | ${(100 * streamCpu).toFixed(1)} % | ` +
    `${long.analysis_s.toFixed(1)} s | ${long.hwm.toFixed(0)} MB | ${long.take_impacts} impacts in its main sequence |`);
} finally {
  await server.stop();
  fs.rmSync(dir, { recursive: true, force: true });
}

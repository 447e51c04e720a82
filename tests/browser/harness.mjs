// Shared by the server's browser test (serve_browser.mjs) and its benchmark (tools/bench_live.mjs):
// `bouncecal serve` on a free port, and Debian's Chromium driven by puppeteer-core (from npm,
// package-lock.json; no browser is downloaded) with a recording as its fake microphone.
import { spawn, execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import puppeteer from 'puppeteer-core';

export function arg(name, fallback) {
  const i = process.argv.indexOf('--' + name);
  return i > 0 && i + 1 < process.argv.length ? process.argv[i + 1] : fallback;
}

export function scratch(tag) {
  return fs.mkdtempSync(path.join(os.tmpdir(), tag + '-'));
}

// The recording as the fake microphone plays it: 16-bit WAV at 44.1 kHz, the rate Chromium's
// fake device runs at (a file at another rate is resampled, and the take is no longer the file);
// with 1 s of digital silence before it (the capture starts with tens of ms of zeros, and a
// step from zeros into the room's noise is an onset to the detector: in silence there is none)
// and `pad_s` after it (past the file's end the fake device beeps, and beeps are impacts).
export function toWav(source, dir, name = 'rec.wav', pad_s = 3) {
  const out = path.join(dir, name);
  execFileSync('ffmpeg', ['-loglevel', 'error', '-y', '-i', source, '-ar', '44100',
    '-af', 'adelay=1000:all=1,apad=pad_dur=' + pad_s, '-c:a', 'pcm_s16le', out]);
  return out;
}

// Starts `bouncecal serve --port 0`; resolves with {url, pid, stop()} once it prints its URL.
export function startServer(bouncecal, extra = []) {
  return new Promise((resolve, reject) => {
    const child = spawn(bouncecal, ['serve', '--port', '0', ...extra], { stdio: ['ignore', 'ignore', 'pipe'] });
    let err = '';
    const timer = setTimeout(() => reject(new Error('the server did not start: ' + err)), 20000);
    child.stderr.on('data', (d) => {
      err += d.toString();
      const m = err.match(/serving (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) {
        clearTimeout(timer);
        resolve({
          url: m[1], pid: child.pid, child, stderr: () => err,
          stop: () => new Promise((done) => { child.once('exit', (code) => done(code)); child.kill('SIGINT'); }),
        });
      }
    });
    child.once('exit', (code) => reject(new Error('the server exited (' + code + '): ' + err)));
  });
}

export function chromiumPath() {
  for (const p of ['/usr/bin/chromium', '/usr/bin/chromium-browser', '/usr/bin/google-chrome']) {
    if (fs.existsSync(p)) return p;
  }
  throw new Error('chromium is missing: run tools/install-deps.sh');
}

// Headless Chromium with a fresh profile; `wav` (if given) plays as the microphone, once.
export async function launch(profileDir, wav) {
  const args = [
    '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--autoplay-policy=no-user-gesture-required', '--window-size=1280,1100',
  ];
  if (wav) {
    args.push('--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream',
      '--use-file-for-fake-audio-capture=' + wav + '%noloop');
  }
  return puppeteer.launch({
    executablePath: chromiumPath(), headless: true, userDataDir: profileDir, args,
    defaultViewport: { width: 1280, height: 1100 },
  });
}

// Every request a page makes, to check that nothing comes from the network.
export function recordRequests(page, origin) {
  const foreign = [];
  page.on('request', (r) => {
    const u = r.url();
    if (!u.startsWith(origin) && !u.startsWith('blob:') && !u.startsWith('data:')) foreign.push(u);
  });
  return foreign;
}

// CPU seconds (user + system) and peak resident memory (MB) of a process.
export function processStats(pid) {
  const stat = fs.readFileSync(`/proc/${pid}/stat`, 'utf8');
  const fields = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
  const ticks = Number(execFileSync('getconf', ['CLK_TCK']).toString());
  const cpu = (Number(fields[11]) + Number(fields[12])) / ticks;
  const status = fs.readFileSync(`/proc/${pid}/status`, 'utf8');
  const hwm = Number((status.match(/VmHWM:\s+(\d+)/) || [0, 0])[1]) / 1024;
  const rss = Number((status.match(/VmRSS:\s+(\d+)/) || [0, 0])[1]) / 1024;
  return { cpu, hwm, rss };
}

// The offset d that puts most live times within 1 ms of a batch time (live = batch + d), and
// the share of the batch's intervals the live ones reproduce (both ends matched, the length
// within 3 combined sigmas + floor_s, default 1 us).
export function compareIntervals(live, batch, floor_s = 1e-6) {
  let best = 0, bestCount = -1;
  for (const l of live) {
    for (const b of batch) {
      const d = l.time_s - b.time_s;
      let n = 0;
      for (const x of live) if (batch.some((y) => Math.abs(x.time_s - y.time_s - d) < 1e-3)) n++;
      if (n > bestCount) { bestCount = n; best = d; }
    }
    if (bestCount === live.length) break;
  }
  let good = 0;
  for (let k = 0; k + 1 < batch.length; k++) {
    const j = live.findIndex((x) => Math.abs(x.time_s - best - batch[k].time_s) < 1e-3);
    if (j < 0 || j + 1 >= live.length) continue;
    if (Math.abs(live[j + 1].time_s - best - batch[k + 1].time_s) >= 1e-3) continue;
    const a = live[j + 1].time_s - live[j].time_s, b = batch[k + 1].time_s - batch[k].time_s;
    const s = Math.hypot(batch[k].time_sigma_s, batch[k + 1].time_sigma_s);
    if (Math.abs(a - b) <= 3 * s + floor_s) good++;
  }
  return { offset_s: best, reproduced: batch.length > 1 ? good / (batch.length - 1) : 0 };
}

// Whether `take` holds the samples of `wav` exactly (from wherever the capture started; its
// first 0.2 s are left out: the fake device's first buffers differ, tens of ms), both decoded to
// 16-bit PCM by ffmpeg and aligned at their first loud sample. A browser starved of CPU drops
// captured audio; a take with a gap is not the file.
export function takeIsTheFile(take, wav) {
  const pcm = (f) => {
    const b = execFileSync('ffmpeg', ['-loglevel', 'error', '-i', f, '-f', 's16le', '-ac', '1', '-'], { maxBuffer: 1 << 28 });
    return new Int16Array(b.buffer, b.byteOffset, b.length >> 1);
  };
  const x = pcm(take), y = pcm(wav);
  const loud = (a) => a.findIndex((v) => Math.abs(v) > 1000);
  const off = loud(x) - loud(y);
  let compared = 0, first = -1, last = -1, count = 0;
  for (let i = Math.max(0, 8820 - off); i < y.length && i + off < x.length; i++, compared++) {
    if (x[i + off] === y[i]) continue;
    if (first < 0) first = i;
    last = i;
    count++;
  }
  return { exact: first < 0 && compared > y.length / 2, first_s: first / 44100, last_s: last / 44100, count, offset: off, compared };
}

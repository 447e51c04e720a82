// bouncecal's page (served by `bouncecal serve`, docs/serve.md). File: a recording is uploaded to
// /api/analyze. Record: the microphone's samples stream over the WebSocket /api/live and every
// impact the server reports is marked as it comes; Stop brings the whole take's analysis. Then
// /api/calibrate, /api/export and /api/report. All numbers come from the server; the page draws.
// For tests and kiosks, window.bouncecal holds the state and ?autostart=1 starts recording.
'use strict';
(function () {
  const $ = (id) => document.getElementById(id);
  const B = (window.bouncecal = {
    mode: 'file',
    file: null,            // File mode: the chosen recording
    take: null,            // Record mode: {id, url} of the finished take
    live: new Map(),       // "seq:index" -> live impact (the final ones, revisions applied)
    bounceOf: new Map(), // "seq:index" -> bounce row of the live analysis
    latencies: [],         // ms from an impact's sound to its message (Record)
    captured_s: 0,         // audio captured so far (Record)
    analysis: null,        // the analysis document shown
    params: null,          // the calibration document
    messages: 0,
    envelope: { min: [], max: [], bucket_s: 0.01 },
  });
  let ws = null, audio = null, takeStartMs = null, drawPending = false;

  function setState(state, text) {
    document.body.dataset.state = state;
    if (text !== undefined) $('status').textContent = text;
  }
  function fail(text) { setState('error', text); }

  // ---- the scene form -> query parameters (the CLI's flags without dashes) ----
  function sceneQuery(withLaw) {
    const p = new URLSearchParams();
    for (const el of $('scene').querySelectorAll('input, select')) {
      if (!el.name || (el.name === 'law' && !withLaw)) continue;
      if (el.type === 'checkbox') { if (el.checked) p.set(el.name, '1'); continue; }
      if (el.value.trim() !== '') p.set(el.name, el.value.trim());
    }
    return p;
  }

  async function request(path, body, params) {
    const res = await fetch(path + '?' + params.toString(), { method: 'POST', body: body });
    if (res.ok) return res;
    let message = res.status + ' ' + res.statusText;
    try { message = (await res.json()).error.message; } catch (e) { /* not JSON */ }
    throw new Error(message);
  }
  function source(params) {
    if (B.mode === 'record' && B.take) { params.set('take', B.take.id); return null; }
    if (B.file) { params.set('name', B.file.name); return B.file; }
    throw new Error('no recording yet');
  }

  // ---- waveform: a min/max envelope in 10 ms buckets, impacts as red marks ----
  function addToEnvelope(x, rate, fromSample) {
    const e = B.envelope, per = Math.max(1, Math.round(e.bucket_s * rate));
    for (let i = 0; i < x.length; i++) {
      const b = Math.floor((fromSample + i) / per);
      if (b >= e.min.length) { e.min.push(x[i]); e.max.push(x[i]); continue; }
      if (x[i] < e.min[b]) e.min[b] = x[i];
      if (x[i] > e.max[b]) e.max[b] = x[i];
    }
  }
  function markTimes() {
    if (B.analysis) return B.analysis.bounces.map((b) => b.time_s);
    return Array.from(B.live.values()).map((i) => i.time_s);
  }
  function scheduleDraw() {
    if (drawPending) return;
    drawPending = true;
    requestAnimationFrame(() => { drawPending = false; drawWave(); drawTable(); drawEv(); });
  }
  function drawWave() {
    const c = $('wave'), g = c.getContext('2d'), e = B.envelope, W = c.width, H = c.height;
    g.fillStyle = '#fff'; g.fillRect(0, 0, W, H);
    const n = e.min.length, duration = Math.max(n * e.bucket_s, 1e-3);
    let peak = 1e-6;
    for (let i = 0; i < n; i++) peak = Math.max(peak, -e.min[i], e.max[i]);
    g.strokeStyle = '#1f77b4'; g.beginPath();
    for (let px = 0; px < W; px++) {
      const b0 = Math.floor(px * n / W), b1 = Math.max(b0 + 1, Math.floor((px + 1) * n / W));
      let lo = 0, hi = 0;
      for (let b = b0; b < b1 && b < n; b++) { lo = Math.min(lo, e.min[b]); hi = Math.max(hi, e.max[b]); }
      g.moveTo(px + 0.5, H / 2 - (hi / peak) * (H / 2 - 12));
      g.lineTo(px + 0.5, H / 2 - (lo / peak) * (H / 2 - 12) + 1);
    }
    g.stroke();
    const times = markTimes();
    g.fillStyle = '#d62728'; g.strokeStyle = 'rgba(214,39,40,0.35)';
    for (const t of times) {
      const x = (t / duration) * W;
      g.beginPath(); g.moveTo(x, 12); g.lineTo(x, H); g.stroke();
      g.beginPath(); g.moveTo(x - 5, 0); g.lineTo(x + 5, 0); g.lineTo(x, 10); g.closePath(); g.fill();
    }
    g.fillStyle = '#555'; g.font = '12px sans-serif';
    g.fillText(duration.toFixed(2) + ' s', W - 60, H - 4);
    c.dataset.marks = String(times.length);
    document.body.dataset.liveImpacts = String(B.live.size);
  }

  // ---- the per-bounce table and the e(v) plot ----
  function fixed(v, d) { return typeof v === 'number' ? v.toFixed(d) : '-'; }
  // As the command line prints a warning: its code, message and what to try next.
  function warningText(w) { return w.code + ': ' + w.message + (w.hint ? '; next: ' + w.hint : ''); }
  function tableRows() {
    if (B.analysis) {
      return B.analysis.bounces.map((b) => ({ seq: B.analysis.sequence, k: b.index, t: b.time_s,
        sigma: b.time_sigma_s, interval: b.interval_s, row: b }));
    }
    const out = [];
    for (const [key, i] of B.live) {
      out.push({ seq: i.sequence, k: i.index, t: i.time_s, sigma: i.time_sigma_s,
        interval: null, row: B.bounceOf.get(key) || null });
    }
    out.sort((a, b) => a.seq - b.seq || a.k - b.k);
    for (let n = 1; n < out.length; n++)
      if (out[n].seq === out[n - 1].seq) out[n - 1].interval = out[n].t - out[n - 1].t;
    return out;
  }
  function drawTable() {
    const body = $('bounces').tBodies[0], rows = tableRows();
    body.textContent = '';
    for (const r of rows) {
      const tr = body.insertRow();
      const e = r.row && typeof r.row.e === 'number'
        ? r.row.e.toFixed(5) + ' \u00b1 ' + fixed(r.row.e_sigma, 6) : '-';
      for (const v of [r.seq, r.k, fixed(r.t, 6), fixed(r.sigma * 1e6, 2), fixed(r.interval, 6), e])
        tr.insertCell().textContent = String(v);
    }
  }
  function drawEv() {
    const c = $('ev'), g = c.getContext('2d'), W = c.width, H = c.height;
    g.fillStyle = '#fff'; g.fillRect(0, 0, W, H);
    const pts = tableRows().map((r) => r.row).filter((b) => b && typeof b.e === 'number' &&
      typeof b.v_in_m_s === 'number' && b.v_in_m_s > 0);
    const curve = B.params && Array.isArray(B.params.e_of_v) ? B.params.e_of_v : [];
    if (!pts.length && !curve.length) { c.dataset.points = '0'; return; }
    let vmin = Infinity, vmax = 0, emin = Infinity, emax = -Infinity;
    for (const b of pts) {
      vmin = Math.min(vmin, b.v_in_m_s); vmax = Math.max(vmax, b.v_in_m_s);
      emin = Math.min(emin, b.e - (b.e_sigma || 0)); emax = Math.max(emax, b.e + (b.e_sigma || 0));
    }
    for (const p of curve) {
      vmin = Math.min(vmin, p.v_m_s); vmax = Math.max(vmax, p.v_m_s);
      emin = Math.min(emin, p.e); emax = Math.max(emax, p.e);
    }
    const pad = Math.max(0.002, 0.08 * (emax - emin));
    emin -= pad; emax += pad;
    const lv0 = Math.log10(vmin) - 0.05, lv1 = Math.log10(vmax) + 0.05, L = 50, B0 = H - 30;
    const X = (v) => L + ((Math.log10(v) - lv0) / (lv1 - lv0)) * (W - L - 10);
    const Y = (e) => B0 - ((e - emin) / (emax - emin)) * (B0 - 10);
    g.strokeStyle = '#999'; g.strokeRect(L, 10, W - L - 10, B0 - 10);
    g.fillStyle = '#333'; g.font = '12px sans-serif';
    g.fillText('e', 8, 20); g.fillText('impact speed v (m/s, log)', W / 2 - 60, H - 8);
    g.fillText(emax.toFixed(3), 4, 22); g.fillText(emin.toFixed(3), 4, B0);
    g.fillText(Math.pow(10, lv0).toPrecision(2), L, H - 16);
    g.fillText(Math.pow(10, lv1).toPrecision(2), W - 40, H - 16);
    if (curve.length) {
      g.strokeStyle = '#2ca02c'; g.lineWidth = 2; g.beginPath();
      curve.forEach((p, n) => (n ? g.lineTo : g.moveTo).call(g, X(p.v_m_s), Y(p.e)));
      g.stroke(); g.lineWidth = 1;
    }
    g.strokeStyle = '#1f77b4'; g.fillStyle = '#1f77b4';
    for (const b of pts) {
      const x = X(b.v_in_m_s), s = b.e_sigma || 0;
      g.beginPath(); g.moveTo(x, Y(b.e - s)); g.lineTo(x, Y(b.e + s)); g.stroke();
      g.beginPath(); g.arc(x, Y(b.e), 3, 0, 2 * Math.PI); g.fill();
    }
    c.dataset.points = String(pts.length);
  }

  // ---- File ----
  async function openFile(file) {
    reset();
    B.file = file;
    setState('analysing', 'Analysing ' + file.name + ' ...');
    try {
      const ctx = new AudioContext();
      const decoded = await ctx.decodeAudioData(await file.arrayBuffer());
      addToEnvelope(decoded.getChannelData(0), decoded.sampleRate, 0);
      ctx.close();
    } catch (e) { /* the server decodes more formats than the browser: no waveform then */ }
    try {
      const params = sceneQuery(false);
      params.set('name', file.name);
      const res = await request('/api/analyze', file, params);
      showAnalysis(await res.json());
    } catch (e) { fail(file.name + ': ' + e.message); }
  }
  function showAnalysis(doc) {
    B.analysis = Array.isArray(doc) ? doc[0] : doc;
    const a = B.analysis, e = a.summary || {};
    setState('ready', a.file + ': ' + a.bounces.length + ' impacts' +
      (typeof e.first_e === 'number' ? ', first e = ' + e.first_e.toFixed(4) : '') +
      '. Fill in the ball to calibrate.');
    $('warnings').textContent = (a.warnings || []).map(warningText).join('\n');
    $('calibrate').disabled = false;
    $('dl-report').hidden = false;
    scheduleDraw();
  }

  // ---- Record ----
  const TAP = `class Tap extends AudioWorkletProcessor {
    constructor() { super(); this.buf = new Float32Array(2048); this.n = 0; }
    process(inputs) {
      const input = inputs[0];
      if (!input || !input.length) return true;
      const frames = input[0].length;
      for (let i = 0; i < frames; i++) {
        let v = 0;
        for (let c = 0; c < input.length; c++) v += input[c][i];
        this.buf[this.n++] = v / input.length;
        if (this.n === this.buf.length) {
          this.port.postMessage(this.buf.slice(0));
          this.n = 0;
        }
      }
      return true;
    }
  }
  registerProcessor('bouncecal-tap', Tap);`;

  async function startRecording() {
    reset();
    setState('starting', 'Opening the microphone ...');
    try {
      const stream = await navigator.mediaDevices.getUserMedia({ audio: {
        echoCancellation: false, noiseSuppression: false, autoGainControl: false, channelCount: 1 } });
      // At the microphone's own rate: no resampling of the impacts' transients.
      const rate = stream.getAudioTracks()[0].getSettings().sampleRate;
      const ctx = new AudioContext(rate ? { sampleRate: rate } : {});
      await ctx.audioWorklet.addModule(URL.createObjectURL(new Blob([TAP], { type: 'text/javascript' })));
      const src = ctx.createMediaStreamSource(stream);
      const tap = new AudioWorkletNode(ctx, 'bouncecal-tap', { numberOfOutputs: 1 });
      const mute = ctx.createGain();
      mute.gain.value = 0;
      src.connect(tap); tap.connect(mute); mute.connect(ctx.destination);
      audio = { stream, ctx, tap, samples: 0 };
      const socket = new WebSocket(location.protocol.replace('http', 'ws') + '//' + location.host +
        '/api/live?' + sceneQuery(false).toString());
      socket.binaryType = 'arraybuffer';
      ws = socket;
      socket.onopen = () => socket.send(JSON.stringify({ rate: ctx.sampleRate }));
      socket.onmessage = (m) => onMessage(JSON.parse(m.data));
      socket.onerror = () => fail('the connection to the server failed');
      socket.onclose = () => { if (document.body.dataset.state === 'recording') fail('the server closed the stream'); };
      tap.port.onmessage = (m) => {
        const x = m.data;
        // The take starts where its first sample was captured: now, less this chunk's duration.
        if (takeStartMs === null) takeStartMs = performance.now() - (x.length / ctx.sampleRate) * 1000;
        if (socket.readyState === WebSocket.OPEN) socket.send(x.buffer);
        addToEnvelope(x, ctx.sampleRate, audio.samples);
        audio.samples += x.length;
        B.captured_s = audio.samples / ctx.sampleRate;
        $('record-info').textContent = (audio.samples / ctx.sampleRate).toFixed(1) + ' s at ' +
          ctx.sampleRate + ' Hz, ' + B.live.size + ' impacts';
        scheduleDraw();
      };
      $('record').disabled = true; $('stop').disabled = false;
      setState('recording', 'Recording: drop the ball.');
    } catch (e) { fail('cannot record: ' + e.message); }
  }
  function stopRecording() {
    if (!audio) return;
    audio.tap.port.onmessage = null;
    for (const t of audio.stream.getTracks()) t.stop();
    audio.ctx.close();
    audio = null;
    $('stop').disabled = true; $('record').disabled = false;
    setState('analysing', 'Analysing the whole take ...');
    if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ stop: true }));
  }
  function onMessage(m) {
    B.messages++;
    if (m.type === 'started') {
      B.session = m.session;
    } else if (m.type === 'impact') {
      const i = m.impact, key = i.sequence + ':' + i.index;
      if (takeStartMs !== null) B.latencies.push(performance.now() - (takeStartMs + i.time_s * 1000));
      B.live.set(key, i);
      if (m.bounce) B.bounceOf.set(i.sequence + ':' + m.bounce.index, m.bounce);
    } else if (m.type === 'revised') {
      for (const key of Array.from(B.live.keys()))
        if (key.startsWith(m.sequence + ':')) { B.live.delete(key); B.bounceOf.delete(key); }
      for (const i of m.impacts) B.live.set(i.sequence + ':' + i.index, i);
      for (const b of m.bounces) B.bounceOf.set(m.sequence + ':' + b.index, b);
    } else if (m.type === 'warning') {
      $('warnings').textContent += warningText(m.warning) + '\n';
    } else if (m.type === 'analysis') {
      B.take = m.take;
      const a = $('dl-take');
      a.href = m.take.url; a.download = 'take.flac'; a.hidden = false;
      if (m.analysis) showAnalysis(m.analysis);
      else fail('the take has no bounce sequence: ' + (m.error ? m.error.message : ''));
    } else if (m.type === 'error') {
      fail(m.error.message);
    }
    scheduleDraw();
  }

  // ---- calibrate, downloads ----
  function download(blob, name) {
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob); a.download = name;
    document.body.appendChild(a); a.click(); a.remove();
  }
  async function calibrate() {
    const params = sceneQuery(true);
    setState('calibrating', 'Calibrating (this can take a minute with all laws) ...');
    try {
      const body = source(params);
      const doc = await (await request('/api/calibrate', body, params)).json();
      const best = doc.laws ? doc.laws.find((l) => l.rank === 1) || doc.laws[0] : doc;
      B.params = best;
      const p = best.law.parameters, f = best.fit;
      const lines = [best.law.name + ': ' + f.outcome + (f.reason ? ' \u2014 ' + f.reason : '') +
        (f.hint ? '; next: ' + f.hint : '')];
      for (const k of Object.keys(p))
        lines.push('  ' + k + ' = ' + p[k].value.toPrecision(6) +
          (typeof p[k].sigma === 'number' ? ' \u00b1 ' + p[k].sigma.toPrecision(2) : '') + ' ' + p[k].unit +
          (p[k].fixed ? ' (held)' : ''));
      if (doc.laws) lines.push('(' + doc.laws.length + ' laws compared; the best shown)');
      $('fit').textContent = lines.join('\n');
      const a = $('dl-params');
      a.href = URL.createObjectURL(new Blob([JSON.stringify(best, null, 2) + '\n'], { type: 'application/json' }));
      a.hidden = false;
      for (const t of ['lammps', 'liggghts', 'yade']) $('dl-' + t).hidden = false;
      setState('calibrated', 'Calibrated: ' + best.law.name + ', ' + best.fit.outcome + '.');
      scheduleDraw();
    } catch (e) { fail('calibration failed: ' + e.message); }
  }
  async function exportDeck(to) {
    try {
      const body = new Blob([JSON.stringify(B.params)], { type: 'application/json' });
      const res = await request('/api/export', body, new URLSearchParams({ to }));
      download(await res.blob(), 'bounce_' + to + '.zip');
    } catch (e) { fail('export to ' + to + ' failed: ' + e.message); }
  }
  async function report() {
    const params = sceneQuery(true);
    try {
      const body = source(params);
      download(await (await request('/api/report', body, params)).blob(), 'report.html');
    } catch (e) { fail('report failed: ' + e.message); }
  }

  function reset() {
    B.file = null; B.take = null; B.analysis = null; B.params = null;
    B.live.clear(); B.bounceOf.clear(); B.latencies = []; B.captured_s = 0; takeStartMs = null;
    B.envelope = { min: [], max: [], bucket_s: 0.01 };
    for (const id of ['dl-take', 'dl-params', 'dl-lammps', 'dl-liggghts', 'dl-yade', 'dl-report'])
      $(id).hidden = true;
    $('fit').textContent = ''; $('warnings').textContent = '';
    $('calibrate').disabled = true;
    scheduleDraw();
  }
  function setMode(mode) {
    B.mode = mode;
    $('mode-file').setAttribute('aria-pressed', String(mode === 'file'));
    $('mode-record').setAttribute('aria-pressed', String(mode === 'record'));
    $('file-panel').hidden = mode !== 'file';
    $('record-panel').hidden = mode !== 'record';
  }

  async function loadLaws() {
    try {
      const res = await fetch('/api/laws');
      for (const law of (await res.json()).laws) {
        const o = document.createElement('option');
        o.value = law.name; o.textContent = law.name;
        if (law.expression === null) $('law').appendChild(o);
      }
    } catch (e) { /* the scene's default law stays available */ }
  }

  $('mode-file').onclick = () => setMode('file');
  $('mode-record').onclick = () => setMode('record');
  $('file-input').onchange = (e) => { if (e.target.files[0]) openFile(e.target.files[0]); };
  const drop = $('drop');
  drop.ondragover = (e) => { e.preventDefault(); drop.classList.add('over'); };
  drop.ondragleave = () => drop.classList.remove('over');
  drop.ondrop = (e) => {
    e.preventDefault(); drop.classList.remove('over');
    if (e.dataTransfer.files[0]) openFile(e.dataTransfer.files[0]);
  };
  $('record').onclick = startRecording;
  $('stop').onclick = stopRecording;
  $('calibrate').onclick = calibrate;
  $('dl-report').onclick = report;
  for (const t of ['lammps', 'liggghts', 'yade']) $('dl-' + t).onclick = () => exportDeck(t);
  loadLaws();
  scheduleDraw();
  if (new URLSearchParams(location.search).get('autostart') === '1') {
    setMode('record');
    startRecording();
  }
})();

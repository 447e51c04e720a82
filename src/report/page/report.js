// bouncecal report page: builds tables and Chart.js charts from the embedded report object
// (schema bouncecal.report/1, see include/bouncecal/report/report_data.hpp). Charts are drawn
// by Chart.js and its plugins (error bars, zoom, annotation); this file only maps data to them.
// After drawing, every chart's canvas carries data-drawn="1" and the number of marks Chart.js
// laid out (data-impact-marks, data-rejected-marks), which the browser test reads back.
(function () {
  'use strict';
  const data = JSON.parse(document.getElementById('bouncecal-data').textContent);
  const root = document.getElementById('report');
  const C = {
    impact: '#d62728', rejected: '#ff7f0e', envelope: '#9ecae1', wave: '#08519c',
    fit: '#2ca02c', band: 'rgba(44,160,44,0.22)', points: '#1f77b4', warning: '#9467bd',
    others: ['#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf', '#ff9896', '#c5b0d5',
             '#c49c94', '#f7b6d2', '#dbdb8d'],
  };

  Chart.register(ChartErrorBars.ScatterWithErrorBarsController, ChartErrorBars.PointWithErrorBar);
  if (typeof ChartZoom !== 'undefined') Chart.register(ChartZoom);
  if (typeof chartjs_plugin_annotation !== 'undefined') Chart.register(chartjs_plugin_annotation);
  Chart.defaults.animation = false;
  Chart.defaults.font.size = 12;

  // ---- small DOM helpers ----
  function el(tag, attrs, children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === 'text') e.textContent = v; else e.setAttribute(k, v);
    }
    for (const c of children || []) e.appendChild(typeof c === 'string' ? document.createTextNode(c) : c);
    return e;
  }
  function fmt(v, digits) {
    if (v === null || v === undefined || !isFinite(v)) return '–';
    return Number(v).toPrecision(digits || 6);
  }
  function table(headers, rows, numericFrom) {
    const t = el('table');
    t.appendChild(el('tr', {}, headers.map((h) => el('th', { text: h }))));
    for (const r of rows) {
      t.appendChild(el('tr', {}, r.map((c, i) =>
        el('td', i >= (numericFrom === undefined ? 99 : numericFrom) ? { class: 'num', text: c } : { text: c }))));
    }
    return t;
  }
  let chartCount = 0;
  function chartBox(id, tall) {
    const box = el('div', { class: tall ? 'chart tall' : 'chart' });
    const canvas = el('canvas', { id: id, 'data-chart': id });
    box.appendChild(canvas);
    return { box, canvas };
  }
  // Records on the canvas what Chart.js actually laid out, once it has drawn.
  const readBack = {
    id: 'bouncecalReadBack',
    afterRender(chart) {
      const canvas = chart.canvas;
      let impacts = 0, rejected = 0, points = 0;
      chart.data.datasets.forEach((ds, i) => {
        const meta = chart.getDatasetMeta(i);
        const n = meta.data.filter((p) => p && isFinite(p.x) && isFinite(p.y)).length;
        if (ds.role === 'impacts') impacts += n;
        if (ds.role === 'rejected') rejected += n;
        if (ds.role === 'points') points += n;
      });
      canvas.setAttribute('data-impact-marks', impacts);
      canvas.setAttribute('data-rejected-marks', rejected);
      canvas.setAttribute('data-point-marks', points);
      const ann = chart.options.plugins && chart.options.plugins.annotation;
      canvas.setAttribute('data-warning-lines', ann && ann.annotations ? Object.keys(ann.annotations).length : 0);
      const r = canvas.getBoundingClientRect();
      canvas.setAttribute('data-rect', [r.left + window.scrollX, r.top + window.scrollY,
        r.width, r.height].map(Math.round).join(','));
      canvas.setAttribute('data-drawn', '1');
    },
  };
  const zoomX = {
    zoom: { wheel: { enabled: true }, drag: { enabled: true }, mode: 'x' },
    pan: { enabled: false },
  };
  function makeChart(canvas, config) {
    config.plugins = (config.plugins || []).concat([readBack]);
    config.options = config.options || {};
    config.options.maintainAspectRatio = false;
    config.options.responsive = true;
    const chart = new Chart(canvas, config);
    canvas.addEventListener('dblclick', () => chart.resetZoom && chart.resetZoom());
    chartCount += 1;
    return chart;
  }
  function resetButton(chartRef) {
    const b = el('button', { text: 'reset zoom' });
    b.addEventListener('click', () => chartRef.chart && chartRef.chart.resetZoom());
    return b;
  }

  // ---- waveform with impacts, rejected candidates, sigma and warnings ----
  function waveformChart(rec, ri) {
    const w = rec.waveform, s = w.scale;
    const env = w.envelope, bin = env.bin_s;
    const envMax = env.max.map((v, i) => ({ x: (i + 0.5) * bin, y: v * s }));
    const envMin = env.min.map((v, i) => ({ x: (i + 0.5) * bin, y: v * s }));
    const full = [];
    for (const win of w.windows) {
      win.samples.forEach((v, i) => full.push({ x: win.start_s + i / w.rate_hz, y: v * s }));
      full.push({ x: win.start_s + win.samples.length / w.rate_hz, y: null });
    }
    const main = rec.main_sequence;
    const impactPoint = (imp) => ({
      x: imp.time_s, y: Math.max(imp.amplitude || 0, 0.02 * w.peak),
      xMin: imp.time_s - (imp.time_sigma_s || 0), xMax: imp.time_s + (imp.time_sigma_s || 0), imp,
    });
    const mainImpacts = rec.impacts.filter((i) => i.sequence === main).map(impactPoint);
    const otherImpacts = rec.impacts.filter((i) => i.sequence !== main).map(impactPoint);
    const rejected = rec.rejected.map((c) => ({ x: c.time_s, y: -Math.max(c.amplitude || 0, 0.02 * w.peak), imp: c }));
    const annotations = {};
    rec.warnings.forEach((wn, i) => {
      if (wn.time_s === null) return;
      annotations['w' + i] = {
        type: 'line', xMin: wn.time_s, xMax: wn.time_s, borderColor: C.warning, borderWidth: 1,
        borderDash: [4, 3],
        label: { display: true, content: wn.code, position: 'start', font: { size: 10 },
                 backgroundColor: 'rgba(148,103,189,0.85)' },
      };
    });
    const datasets = [
      { type: 'line', label: 'min/max envelope', data: envMax, borderColor: C.envelope, borderWidth: 1,
        backgroundColor: 'rgba(158,202,225,0.5)', pointRadius: 0, fill: '+1', order: 5 },
      { type: 'line', label: 'envelope (min)', data: envMin, borderColor: C.envelope, borderWidth: 1,
        pointRadius: 0, fill: false, order: 5 },
      { type: 'line', label: 'full resolution near onsets', data: full, borderColor: C.wave,
        borderWidth: 1, pointRadius: 0, spanGaps: false, order: 4 },
      { type: 'scatterWithErrorBars', role: 'impacts', label: 'impacts (main sequence) ± σ',
        data: mainImpacts, backgroundColor: C.impact, borderColor: C.impact, pointStyle: 'triangle',
        pointRadius: 6, errorBarColor: C.impact, errorBarWhiskerColor: C.impact, order: 1 },
      { type: 'scatterWithErrorBars', role: 'impacts', label: 'impacts (other sequences) ± σ',
        data: otherImpacts, backgroundColor: '#fff', borderColor: C.impact, pointStyle: 'triangle',
        pointRadius: 6, errorBarColor: C.impact, errorBarWhiskerColor: C.impact, order: 2 },
      { type: 'scatter', role: 'rejected', label: 'rejected candidates', data: rejected,
        borderColor: C.rejected, backgroundColor: C.rejected, pointStyle: 'crossRot', pointRadius: 7,
        borderWidth: 2, order: 3 },
    ];
    const ref = {};
    const { box, canvas } = chartBox('waveform-' + ri, true);
    ref.chart = makeChart(canvas, {
      type: 'scatterWithErrorBars',
      data: { datasets },
      options: {
        normalized: true,
        scales: { x: { type: 'linear', title: { display: true, text: 'time (s)' } },
                  y: { title: { display: true, text: 'amplitude (full scale)' } } },
        plugins: {
          zoom: zoomX, annotation: { annotations },
          legend: { labels: { filter: (item) => !item.text.startsWith('envelope (min)') } },
          tooltip: { callbacks: { label: (ctx) => {
            const p = ctx.raw;
            if (!p.imp) return ctx.dataset.label + ': ' + fmt(p.x, 7) + ' s';
            const i = p.imp;
            return (ctx.dataset.role === 'rejected' ? 'rejected: ' + (i.reason || '') + ', ' : 'impact ' + i.index + ': ') +
              't = ' + fmt(i.time_s, 8) + ' s ± ' + fmt(i.time_sigma_s * 1e6, 3) + ' µs, SNR ' + fmt(i.snr_db, 3) + ' dB';
          } } },
        },
      },
    });
    return [el('div', {}, [resetButton(ref)]), box];
  }

  function intervalsChart(rec, ri) {
    const pts = rec.intervals.map((iv) => ({
      x: iv.index, y: iv.interval_s, yMin: iv.interval_s - (iv.interval_sigma_s || 0), yMax: iv.interval_s + (iv.interval_sigma_s || 0),
    }));
    const { box, canvas } = chartBox('intervals-' + ri);
    makeChart(canvas, {
      type: 'scatterWithErrorBars',
      data: { datasets: [{ role: 'points', label: 'interval t(k+1) − t(k) ± σ', data: pts,
        backgroundColor: C.points, borderColor: C.points, pointRadius: 3 }] },
      options: { scales: {
        x: { type: 'linear', title: { display: true, text: 'bounce k' } },
        y: { title: { display: true, text: 'interval (s)' } } } },
    });
    return box;
  }

  function residualsChart(rec, ri) {
    const r = rec.residuals;
    const us = r.unit === 's' ? 1e6 : 1;
    const pts = r.values.filter((v) => v.residual !== null).map((v) => {
      const sg = v.sigma === null ? 0 : v.sigma * us;
      return { x: v.index, y: v.residual * us, yMin: v.residual * us - sg, yMax: v.residual * us + sg };
    });
    const { box, canvas } = chartBox('residuals-' + ri);
    makeChart(canvas, {
      type: 'scatterWithErrorBars',
      data: { datasets: [{ role: 'points', label: 'model − measured' + (r.unit === 's' ? ' (± onset σ)' : ''),
        data: pts, backgroundColor: C.fit, borderColor: C.fit, pointRadius: 3, errorBarColor: C.fit,
        errorBarWhiskerColor: C.fit }] },
      options: { scales: {
        x: { type: 'linear', title: { display: true, text: r.unit === 's' ? 'impact k' : 'e point' } },
        y: { title: { display: true, text: r.unit === 's' ? 'residual (µs)' : 'residual in e' } } } },
    });
    return box;
  }

  // ---- restitution against impact speed, fitted e(v) with its band, other laws ----
  function restitutionChart() {
    const datasets = [];
    data.recordings.forEach((rec, ri) => {
      const pts = rec.bounces.filter((b) => b.e !== null && b.v_in_m_s !== null).map((b) => ({
        x: b.v_in_m_s, y: b.e, yMin: b.e - (b.e_sigma || 0), yMax: b.e + (b.e_sigma || 0),
        xMin: b.v_in_m_s - (b.v_in_sigma_m_s || 0), xMax: b.v_in_m_s + (b.v_in_sigma_m_s || 0),
      }));
      datasets.push({ type: 'scatterWithErrorBars', role: 'points',
        label: 'measured e ± σ' + (data.recordings.length > 1 ? ' (' + rec.file + ')' : ''),
        data: pts, backgroundColor: ri === 0 ? C.points : C.others[ri % C.others.length],
        borderColor: ri === 0 ? C.points : C.others[ri % C.others.length], pointRadius: 3, order: 1 });
    });
    const fit = data.fit;
    if (fit && fit.e_of_v && fit.e_of_v.length) {
      const ev = fit.e_of_v.filter((p) => p.e !== null);
      const hi = ev.map((p) => ({ x: p.v_m_s, y: p.e + (p.e_sigma || 0) }));
      const lo = ev.map((p) => ({ x: p.v_m_s, y: p.e - (p.e_sigma || 0) }));
      datasets.push({ type: 'line', label: 'fit ' + fit.law.name + ' e(v) + σ', data: hi, borderColor: 'rgba(0,0,0,0)',
        backgroundColor: C.band, pointRadius: 0, fill: '+1', order: 3 });
      datasets.push({ type: 'line', label: 'fit band − σ', data: lo, borderColor: 'rgba(0,0,0,0)', pointRadius: 0,
        fill: false, order: 3 });
      datasets.push({ type: 'line', label: 'fit ' + fit.law.name + ' e(v)', data: ev.map((p) => ({ x: p.v_m_s, y: p.e })),
        borderColor: C.fit, borderWidth: 2, pointRadius: 0, tension: 0.3, order: 2 });
    }
    data.law_comparison.slice(1).forEach((row, i) => {
      if (!row.e_of_v.length) return;
      datasets.push({ type: 'line', label: row.law.name + ' (ΔAIC ' + fmt(row.delta_aic, 3) + ')',
        data: row.e_of_v.filter((p) => p.e !== null).map((p) => ({ x: p.v_m_s, y: p.e })),
        borderColor: C.others[i % C.others.length], borderDash: [5, 4], borderWidth: 1.5, pointRadius: 0,
        tension: 0.3, order: 4 });
    });
    const { box, canvas } = chartBox('restitution', true);
    const ref = {};
    ref.chart = makeChart(canvas, {
      type: 'scatterWithErrorBars',
      data: { datasets },
      options: { scales: {
        x: { type: 'logarithmic', title: { display: true, text: 'impact speed v_in (m/s)' } },
        y: { title: { display: true, text: 'restitution e' } } },
        plugins: { zoom: { zoom: { wheel: { enabled: true }, drag: { enabled: true }, mode: 'xy' } },
                   legend: { labels: { filter: (item) => !item.text.startsWith('fit band') } } } },
    });
    return [el('div', {}, [resetButton(ref)]), box];
  }

  function energyChart() {
    const e = data.energy;
    const sim = e.impacts.map((i) => ({ x: i.time_s, y: i.kinetic_in_j }));
    const datasets = [{ type: 'line', label: 'simulated kinetic energy at impact (fitted law)', data: sim,
      borderColor: C.fit, pointRadius: 1.5, borderWidth: 1, order: 2 }];
    data.recordings.forEach((rec, ri) => {
      if (ri > 0) return;  // the ledger simulates the first recording's drop
      const m = e.mass_kg;
      const pts = rec.bounces.filter((b) => b.v_in_m_s !== null).map((b) => ({
        x: b.time_s, y: 0.5 * m * b.v_in_m_s * b.v_in_m_s,
        // sigma(E) = m v sigma(v)
        yMin: 0.5 * m * b.v_in_m_s * b.v_in_m_s - m * b.v_in_m_s * (b.v_in_sigma_m_s || 0),
        yMax: 0.5 * m * b.v_in_m_s * b.v_in_m_s + m * b.v_in_m_s * (b.v_in_sigma_m_s || 0),
      }));
      datasets.push({ type: 'scatterWithErrorBars', role: 'points', label: 'measured ½ m v_in²', data: pts,
        backgroundColor: C.points, borderColor: C.points, pointRadius: 3, order: 1 });
    });
    const { box, canvas } = chartBox('energy');
    makeChart(canvas, { type: 'scatterWithErrorBars', data: { datasets },
      options: { scales: {
        x: { type: 'linear', title: { display: true, text: 'time (s)' } },
        y: { type: 'logarithmic', title: { display: true, text: 'kinetic energy at impact (J)' },
             ticks: { callback: (v) => Number(v).toExponential(0) } } } } });
    return box;
  }

  // ---- tables ----
  function warningsList(warnings) {
    if (!warnings.length) return el('p', { class: 'hint', text: 'No warnings.' });
    return el('ul', { class: 'warnings' }, warnings.map((w) => el('li', {}, [
      el('code', { text: w.code }), ' ' + w.message +
      (w.time_s !== undefined && w.time_s !== null ? ' (t = ' + fmt(w.time_s, 7) + ' s)' : ''),
      ...(w.hint ? [el('br'), el('span', { class: 'next-step', text: 'Next: ' + w.hint })] : [])])));
  }
  function parameterTable(fit) {
    const names = Object.keys(fit.law.parameters);
    return table(['parameter', 'value', 'σ', 'unit', 'status'], names.map((n) => {
      const p = fit.law.parameters[n];
      const status = p.fixed ? 'held' + (p.determined ? ' (the data could fit it)' : '')
        : (p.determined ? 'fitted' : 'not determined') + (p.at_bound ? ', at bound' : '');
      return [n, fmt(p.value, 7), p.sigma === null ? '–' : fmt(p.sigma, 3), p.unit, status];
    }), 1);
  }
  function fitStatsTable(fit) {
    const f = fit.fit;
    const rms = f.rms_residual_s !== undefined ? fmt(f.rms_residual_s * 1e6, 4) + ' µs' : fmt(f.rms_residual_e, 4);
    return table(['strategy', 'outcome', 'rms residual', 'χ²/dof', 'dof', 'AIC', 'BIC', 'iterations'],
      [[f.strategy, f.outcome, rms, fmt(f.chi2_dof, 4), String(f.dof), fmt(f.aic, 6), fmt(f.bic, 6), String(f.iterations)]], 2);
  }
  function lawTable() {
    return table(['rank', 'law', 'outcome', 'ΔAIC', 'χ²/dof', 'rms residual', 'why not ranked; next step'],
      data.law_comparison.map((r) => [
        String(r.rank), r.law.name, r.outcome, fmt(r.delta_aic, 4), fmt(r.chi2_dof, 4),
        r.rms_residual === null ? r.message : fmt(r.rms_residual, 4) + ' ' + r.residual_unit,
        r.outcome === 'converged' ? '' : r.reason + (r.hint ? ' — Next: ' + r.hint : '')]), 3);
  }
  function energyTable(e) {
    const rows = [['initial (potential + kinetic)', e.initial_j], ['final mechanical', e.final_mechanical_j],
      ['dissipated in contacts', e.dissipated_contact_j], ['dissipated by drag', e.dissipated_drag_j],
      ['held in the law (internal)', e.internal_j], ['balance error', e.balance_error_j]];
    return table(['energy', 'J', 'fraction of initial'], rows.map(([n, v]) => [n, fmt(v, 6), fmt(v / e.initial_j, 4)]), 1);
  }
  function provenanceBlock() {
    const p = data.provenance;
    const box = el('div');
    box.appendChild(table(['input', 'sha256'], p.inputs.map((i) => [i.file, i.sha256])));
    box.appendChild(table(['bouncecal version', 'date (UTC)', 'command'],
      [[p.bouncecal_version, p.date_utc, p.command === null ? '–' : p.command]]));
    box.appendChild(el('details', {}, [el('summary', { text: 'options' }),
      el('pre', { class: 'mono', text: JSON.stringify(p.options, null, 2) })]));
    return box;
  }
  function bouncesTable(rec) {
    return el('details', {}, [el('summary', { text: 'per-bounce table (' + rec.bounces.length + ' impacts)' }),
      table(['k', 'time (s)', 'σ (µs)', 'v_in (m/s)', 'σ', 'e', 'σ'], rec.bounces.map((b) => [
        String(b.index), fmt(b.time_s, 8), fmt(b.time_sigma_s * 1e6, 3), fmt(b.v_in_m_s, 6),
        fmt(b.v_in_sigma_m_s, 2), fmt(b.e, 6), fmt(b.e_sigma, 2)]), 1)]);
  }

  // ---- the page ----
  function build() {
    const files = data.recordings.map((r) => r.file).join(', ');
    document.getElementById('subtitle').textContent = files +
      (data.fit ? ' — law ' + data.fit.law.name + ', fit ' + data.fit.fit.outcome : ' — no fit');
    data.recordings.forEach((rec, ri) => {
      const sec = el('section', { id: 'recording-' + ri });
      sec.appendChild(el('h2', { text: 'Recording ' + rec.file }));
      sec.appendChild(el('p', { class: 'hint', text: fmt(rec.sample_rate_hz, 6) + ' Hz, ' + rec.channels +
        ' channel(s), ' + (rec.channel === null ? 'the mix' : 'channel ' + rec.channel) + ' shown, ' + fmt(rec.duration_s, 5) + ' s, ' + rec.format + '; ' +
        rec.impacts.length + ' impacts detected in ' + rec.sequences.length + ' sequence(s), ' +
        rec.rejected.length + ' rejected candidates' +
        (rec.waveform.windows_dropped ? '; ' + rec.waveform.windows_dropped + ' onset windows beyond the size budget show the envelope only' : '') }));
      if (rec.no_impacts_reason !== null) {
        sec.appendChild(el('p', { class: 'alert bad', id: 'no-impacts-' + ri, text: 'No impacts to analyse: ' + rec.no_impacts_reason }));
      }
      sec.appendChild(el('h3', { text: 'Warnings' }));
      sec.appendChild(warningsList(rec.warnings));
      sec.appendChild(el('h3', { text: 'Waveform, detected impacts (▲, ± σ in time) and rejected candidates (✕)' }));
      waveformChart(rec, ri).forEach((n) => sec.appendChild(n));
      if (rec.intervals.length) {
        sec.appendChild(el('h3', { text: 'Intervals per bounce' }));
        sec.appendChild(intervalsChart(rec, ri));
      }
      if (rec.residuals !== null && rec.residuals.values.length) {
        sec.appendChild(el('h3', { text: 'Fit residuals per impact' }));
        sec.appendChild(residualsChart(rec, ri));
      }
      if (rec.bounces.length) sec.appendChild(bouncesTable(rec));
      root.appendChild(sec);
    });
    const anyBounces = data.recordings.some((r) => r.bounces.length);
    const fitSec = el('section', { id: 'fit' });
    fitSec.appendChild(el('h2', { text: 'Restitution and fit' }));
    if (data.fit_failure !== null) fitSec.appendChild(el('p', { class: 'alert bad', text: 'No fit: ' + data.fit_failure }));
    if (data.fit) {
      if (data.fit.fit.outcome !== 'converged') {
        fitSec.appendChild(el('p', { class: 'alert', id: 'fit-outcome', text: 'Fit outcome ' + data.fit.fit.outcome + ': ' + data.fit.fit.reason }));
      }
      if (data.fit.fit.hint) {
        fitSec.appendChild(el('p', { class: 'next-step', id: 'fit-hint', text: 'Next: ' + data.fit.fit.hint }));
      }
      if (data.fit.warnings.length) {
        fitSec.appendChild(el('h3', { text: 'Fit warnings' }));
        fitSec.appendChild(warningsList(data.fit.warnings));
      }
      fitSec.appendChild(el('p', {}, [el('b', { text: data.fit.law.name + ': ' }), data.fit.law.formula]));
      fitSec.appendChild(parameterTable(data.fit));
      fitSec.appendChild(fitStatsTable(data.fit));
    }
    if (anyBounces) {
      fitSec.appendChild(el('h3', { text: 'Restitution e against impact speed' + (data.fit ? ', fitted e(v) ± σ' : '') +
        (data.law_comparison.length > 1 ? ', other laws (dashed)' : '') }));
      restitutionChart().forEach((n) => fitSec.appendChild(n));
    }
    if (data.law_comparison.length) {
      fitSec.appendChild(el('h3', { text: 'Law comparison (ranked by AIC)' }));
      fitSec.appendChild(lawTable());
    }
    root.appendChild(fitSec);
    if (data.energy) {
      const en = el('section', { id: 'energy' });
      en.appendChild(el('h2', { text: 'Energy ledger (simulated at the fitted parameters)' }));
      en.appendChild(el('p', { class: 'hint', text: data.energy.impacts.length + ' simulated impacts, stop: ' +
        data.energy.stop_reason + (data.energy.stop_detail ? ' (' + data.energy.stop_detail + ')' : '') }));
      en.appendChild(energyTable(data.energy));
      en.appendChild(energyChart());
      root.appendChild(en);
    }
    const pv = el('section', { id: 'provenance' });
    pv.appendChild(el('h2', { text: 'Provenance' }));
    pv.appendChild(provenanceBlock());
    root.appendChild(pv);
  }

  try {
    build();
    document.body.setAttribute('data-charts', chartCount);
    document.body.setAttribute('data-page-height', Math.ceil(document.documentElement.scrollHeight));
    document.body.setAttribute('data-report-state', 'drawn');
  } catch (err) {
    document.body.setAttribute('data-report-state', 'error');
    document.body.setAttribute('data-report-error', String(err && err.stack || err));
    root.appendChild(el('p', { class: 'alert bad', text: 'The report page failed: ' + err }));
  }
})();

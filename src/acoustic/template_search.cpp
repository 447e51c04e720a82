// The template pass of onset detection: the whitened waveform of the strongest onset, its
// normalised cross-correlation with the whole signal (FFT overlap-save, chunk by chunk), the
// template timing of the clear matches, the blind search for the onsets the flux missed, and
// the guided search (FindByTemplate). See include/bouncecal/acoustic/onsets.hpp.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <utility>
#include <vector>

#include "avx2_clones.hpp"
#include "bouncecal/core/parallel.hpp"
#include "spectra.hpp"

namespace bouncecal {
namespace {

// Overlap-save blocks of the template correlation per task.
constexpr std::size_t kCorrelatePart = 8;
// Running-energy restarts (samples) of the template energy, and how many per task (a multiple
// of 4: RunningEnergy4).
constexpr std::size_t kEnergyRestart = 8192;
constexpr std::size_t kEnergyPart = 4;

// The template, and its normalised cross-correlation with the whitened signal, computed a chunk
// at a time: the correlation xc[i] = sum_j h[j] w[i + j] and the energy under the template
// ww[i] = sum of w^2 over [i, min(n, i + tl)) of every template start i. Both were whole-block
// float arrays (46 MB for a 2-minute block at 48 kHz, 40 % of the detection's memory, all of it
// first touched per block); a chunk holds kNccChunk starts, and each value is computed the same
// way wherever the chunk starts (xc from the overlap-save block of the whole signal that holds
// it, ww from its kEnergyRestart stretch), so the values are the same to the bit. 65536 starts
// per chunk: the kept chunks take 2 MB; with 262144 they took 8 MB and a 1-minute detection's
// peak memory was 50 against 45 MB, in the same time (31 alternating runs, two threads: 68.4
// against 68.2 ms median).
constexpr std::size_t kNccChunk = 8 * kEnergyRestart;
constexpr std::size_t kNccChunksKept = 4;

}  // namespace

struct OnsetDetector::TemplateMatch {
  double hh = 0.0;
  long ref_start = 0;  // template start sample
  double t_ref = 0.0;  // its onset time (AIC pick of the strongest onset)
  long lead = 0;       // samples from the template start to its onset
  long n = 0;          // template starts (samples of the whitened signal)
};

// NCC values of one stretch of template starts [begin, begin + xc.size()), kept for later.
struct OnsetDetector::NccWindow {
  long begin = 0;
  std::vector<float> xc, ww;
};

namespace {

// The first k in [k0, k1) where xc[k] > 0 and not xc[k]^2 < k2 ww[k] (in double, as the blind
// search asks), k1 if none: eight starts at a time (GCC/Clang vector extension, the same double
// operations per lane), the few that pass looked at one by one.
BOUNCECAL_AVX2_CLONES
std::size_t NextNccCandidate(const float* xc, const float* ww, std::size_t k0, std::size_t k1,
                             double k2) {
  typedef float Float4 __attribute__((vector_size(16)));
  typedef double Double4v __attribute__((vector_size(32)));
  typedef long long Long4 __attribute__((vector_size(32)));
  auto passes = [&](std::size_t k) {
    const double c = xc[k], e = ww[k];
    return (c > 0.0) & !(c * c < k2 * e);
  };
  std::size_t k = k0;
  const Double4v zero = {0.0, 0.0, 0.0, 0.0};
  const Double4v k2v = {k2, k2, k2, k2};
  for (; k + 8 <= k1; k += 8) {
    Long4 any = {0, 0, 0, 0};
    for (std::size_t h = 0; h < 8; h += 4) {
      Float4 cf, ef;
      std::memcpy(&cf, xc + k + h, sizeof cf);
      std::memcpy(&ef, ww + k + h, sizeof ef);
      const Double4v cv = __builtin_convertvector(cf, Double4v);
      const Double4v ev = __builtin_convertvector(ef, Double4v);
      any |= (cv > zero) & ~(cv * cv < k2v * ev);
    }
    if (any[0] | any[1] | any[2] | any[3]) break;
  }
  for (; k < k1; ++k)
    if (passes(k)) return k;
  return k1;
}

// ww[i - base] = sum of w^2 over [i, min(n, i + tl)) for i in [b, e): exact at b, then running.
void RunningEnergy(const std::vector<float>& w, std::size_t tl, std::size_t b, std::size_t e,
                   std::size_t base, float* ww) {
  const std::size_t n = w.size();
  double run = 0.0;
  for (std::size_t j = b; j < std::min(n, b + tl); ++j) run += static_cast<double>(w[j]) * w[j];
  ww[b - base] = static_cast<float>(run);
  const std::size_t e_in = std::min(e, n - std::min(n, tl - 1));  // w[i + tl - 1] exists
  std::size_t i = b + 1;
  for (; i < e_in; ++i) {
    const double in_v = w[i + tl - 1], out_v = w[i - 1];
    run += in_v * in_v - out_v * out_v;
    ww[i - base] = static_cast<float>(std::max(run, 0.0));
  }
  for (; i < e; ++i) {
    const double out_v = w[i - 1];
    run -= out_v * out_v;
    ww[i - base] = static_cast<float>(std::max(run, 0.0));
  }
}

// RunningEnergy on the four whole stretches starting at b, b + kEnergyRestart, ... (all of
// w[i + tl - 1] inside w): the same operations per stretch, interleaved, so that the four
// running sums' additions overlap (one sum alone is a chain of dependent additions).
void RunningEnergy4(const std::vector<float>& w, std::size_t tl, std::size_t b, std::size_t base,
                    float* ww) {
  double run[4];
  for (std::size_t q = 0; q < 4; ++q) {
    const std::size_t bq = b + q * kEnergyRestart;
    run[q] = 0.0;
    for (std::size_t j = bq; j < bq + tl; ++j) run[q] += static_cast<double>(w[j]) * w[j];
    ww[bq - base] = static_cast<float>(run[q]);
  }
  for (std::size_t i = 1; i < kEnergyRestart; ++i)
    for (std::size_t q = 0; q < 4; ++q) {
      const std::size_t at = b + q * kEnergyRestart + i;
      const double in_v = w[at + tl - 1], out_v = w[at - 1];
      run[q] += in_v * in_v - out_v * out_v;
      ww[at - base] = static_cast<float>(std::max(run[q], 0.0));
    }
}

}  // namespace

// The chunks of xc and ww, computed on demand and kept (the kNccChunksKept used last): the
// template pass reads them in time order, so each is computed once.
struct OnsetDetector::NccChunks {
  const Correlator& corr;
  const std::vector<float>& w;
  const std::vector<double>& h;
  double hh;
  int threads;
  FftArrays tf;  // the template's spectrum
  struct Chunk {
    long index = -1;
    unsigned long used = 0;
    FloatBuffer xc, ww;
  };
  Chunk kept[kNccChunksKept];
  unsigned long clock = 0;

  NccChunks(const Correlator& c, const std::vector<float>& whitened, const std::vector<double>& tpl,
            double tpl_energy, int n_threads)
      : corr(c),
        w(whitened),
        h(tpl),
        hh(tpl_energy),
        threads(n_threads),
        tf(static_cast<std::size_t>(c.n)) {
    corr.TemplateSpectrum(h, &tf);
  }

  const Chunk& Get(std::size_t index) {
    Chunk* slot = &kept[0];
    for (Chunk& c : kept) {
      if (c.index == static_cast<long>(index)) {
        c.used = ++clock;
        return c;
      }
      if (c.used < slot->used) slot = &c;
    }
    Compute(index, slot);
    slot->used = ++clock;
    return *slot;
  }

  void Compute(std::size_t index, Chunk* c) {
    const std::size_t n = w.size(), tl = h.size();
    const std::size_t lo = index * kNccChunk, hi = std::min(n, lo + kNccChunk);
    if (c->xc.size() < kNccChunk) {
      c->xc.Allocate(kNccChunk);
      c->ww.Allocate(kNccChunk);
    }
    c->index = static_cast<long>(index);
    // The correlation's blocks and the energy's stretches are independent (the restarts make
    // the stretches so; kNccChunk is a multiple of kEnergyRestart): one set of tasks, groups of
    // kCorrelatePart blocks and of kEnergyPart stretches, on the threads. (The two as separate
    // ParallelFor calls of larger groups: the energy's one group ran alone, and a 1-minute
    // recording's template pass took 12 ms on one thread and on two alike.)
    const std::size_t blocks = corr.Blocks(tl, lo, hi);
    const std::size_t ctasks = (blocks + kCorrelatePart - 1) / kCorrelatePart;
    const std::size_t s0 = lo / kEnergyRestart, s1 = (hi + kEnergyRestart - 1) / kEnergyRestart;
    const std::size_t etasks = (s1 - s0 + kEnergyPart - 1) / kEnergyPart;
    float* xc = c->xc.data.get();
    float* ww = c->ww.data.get();
    ParallelFor(threads, ctasks + etasks, [&](std::size_t task) {
      if (task < ctasks) {
        FftArrays a(static_cast<std::size_t>(corr.n));
        corr.CorrelateBlocks(w, tf.spec, tl, lo, hi, task * kCorrelatePart,
                             std::min(blocks, (task + 1) * kCorrelatePart), xc, &a);
        return;
      }
      const std::size_t g = task - ctasks;
      std::size_t b = (s0 + g * kEnergyPart) * kEnergyRestart;
      const std::size_t end = std::min(s1, s0 + (g + 1) * kEnergyPart) * kEnergyRestart;
      for (; b + 4 * kEnergyRestart <= end && b + 4 * kEnergyRestart + tl <= n + 1;
           b += 4 * kEnergyRestart)
        RunningEnergy4(w, tl, b, lo, ww);
      for (; b < end; b += kEnergyRestart)
        RunningEnergy(w, tl, b, std::min(n, b + kEnergyRestart), lo, ww);
    });
  }

  double Ncc(std::size_t i) {
    const Chunk& c = Get(i / kNccChunk);
    const std::size_t k = i - static_cast<std::size_t>(c.index) * kNccChunk;
    const double e = c.ww[k];
    return e > 0.0 ? static_cast<double>(c.xc[k]) / std::sqrt(hh * e) : 0.0;
  }

  // xc and ww over [a, b] (inclusive, inside [0, n)), for later.
  void Keep(long a, long b, NccWindow* out) {
    out->begin = a;
    out->xc.resize(static_cast<std::size_t>(b - a + 1));
    out->ww.resize(out->xc.size());
    for (long i = a; i <= b; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Chunk& c = Get(u / kNccChunk);
      const std::size_t k = u - static_cast<std::size_t>(c.index) * kNccChunk;
      out->xc[static_cast<std::size_t>(i - a)] = c.xc[k];
      out->ww[static_cast<std::size_t>(i - a)] = c.ww[k];
    }
  }
};

bool OnsetDetector::BuildTemplate(OnsetResult* res, double template_onset_s,
                                  TemplateMatch* m) const {
  const std::vector<float>& w = res->whitened;
  const std::size_t n = w.size();
  std::size_t strongest = 0;
  for (std::size_t i = 1; i < res->onsets.size(); ++i)
    if (res->onsets[i].snr_db > res->onsets[strongest].snr_db) strongest = i;
  for (std::size_t i = 0; i < res->onsets.size(); ++i)
    if (res->onsets[i].time_s == template_onset_s) strongest = i;
  m->lead = static_cast<long>(0.1e-3 * rate_hz_) + 1;
  const std::size_t tl = static_cast<std::size_t>(template_len_);
  m->ref_start = std::lround(res->onsets[strongest].time_s * rate_hz_) - m->lead;
  if (m->ref_start < 0 || static_cast<std::size_t>(m->ref_start) + tl > n) return false;
  std::vector<double> h(tl);
  for (std::size_t j = 0; j < tl; ++j) {
    h[j] = w[static_cast<std::size_t>(m->ref_start) + j];
    m->hh += h[j] * h[j];
  }
  if (!(m->hh > 0.0)) return false;
  res->template_wave = h;
  res->template_start = m->ref_start;
  res->template_onset_s = res->onsets[strongest].time_s;
  m->t_ref = res->onsets[strongest].time_s;
  m->n = static_cast<long>(n);
  return true;
}

void OnsetDetector::TimeWithTemplate(const TemplateMatch& m, const std::function<double(long)>& ncc,
                                     long lo, long hi, Impact* im) const {
  // The impacts of one ball on one plate have the same waveform up to level, so the
  // cross-correlation lag to the template times them relative to the template's own onset far
  // more consistently than an AIC pick on each: the AIC moves with the level (it finds the first
  // sample that stands out of the background, later for a quiet impact) and jumps to a later
  // rise when the onset is weak or slow. Measured on the corpus (steel on copper, ping-pong on
  // wood): AIC picks scatter by 5-30 us around the truth and a few jump by 30-2000 us; NCC lags
  // scatter by 1-5 us (tools/bench_detect). Every impact with a clear match
  // (NCC >= template_timing_ncc) is therefore timed by the template. t_guess: the AIC pick;
  // [lo, hi]: template starts the AIC window allowed (the pick can land anywhere in it).
  const long n = m.n;
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long s0 = std::lround(im->time_s * rate_hz_) - m.lead;
  // Best NCC within +-maxlag of the guess; a farther one (in the AIC window or 2 maxlag around
  // the guess) only if it is clearly better (ball ringing and echoes also match).
  long best_l = -1, far_l = -1;
  double best_c = -2.0, far_c = -2.0;
  const long from = std::max(1L, std::min(lo, s0 - 2 * maxlag));
  const long to = std::min(n - 2, std::max(hi, s0 + 2 * maxlag));
  for (long l = from; l <= to; ++l) {
    const double c = ncc(l);
    const bool near = std::labs(l - s0) <= maxlag;
    if (near && c > best_c) {
      best_c = c;
      best_l = l;
    }
    if (!near && c > far_c) {
      far_c = c;
      far_l = l;
    }
  }
  if (far_c > best_c + 0.15) {
    best_c = far_c;
    best_l = far_l;
  }
  if (best_c < options_.template_timing_ncc || best_l < 1) return;
  const double cm = ncc(best_l - 1);
  const double cp = ncc(best_l + 1);
  const double curv = cm - 2.0 * best_c + cp;
  const double d = curv < 0.0 ? std::clamp(0.5 * (cm - cp) / curv, -0.5, 0.5) : 0.0;
  im->time_s = m.t_ref + (static_cast<double>(best_l - m.ref_start) + d) / rate_hz_;
  im->score = std::max(im->score, std::min(best_c, 1.0));
  // NCC peak precision ~ sqrt(1 - c^2) / c samples (scaled), plus the floor. (The final timing
  // of sequence members, with its calibrated sigma, is timing.hpp's.)
  const double sig_samples = 0.3 * std::sqrt(std::max(0.0, 1.0 - best_c * best_c)) / best_c;
  im->sigma_s =
      std::hypot(sig_samples / rate_hz_,
                 std::max(options_.sigma_floor_s, options_.sigma_floor_samples / rate_hz_));
}

// Template starts TimeWithTemplate reads for an impact at time_s ([lo, hi]: as it is given):
// [from - 1, to + 1] inside [0, n).
std::pair<long, long> OnsetDetector::TimingStarts(const TemplateMatch& m, long lo, long hi,
                                                  double time_s) const {
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long s0 = std::lround(time_s * rate_hz_) - m.lead;
  const long from = std::max(1L, std::min(lo, s0 - 2 * maxlag));
  const long to = std::min(m.n - 2, std::max(hi, s0 + 2 * maxlag));
  return {std::max(0L, from - 1), std::min(m.n - 1, to + 1)};
}

// A start where the NCC with the template reaches the blind search's threshold (the best of
// its run), and the NCC around it that timing it will read.
struct OnsetDetector::BlindCandidate {
  std::size_t start = 0;
  double ncc = 0.0;
  NccWindow window;
};

void OnsetDetector::BlindScan(const TemplateMatch& m, NccChunks* chunks, std::size_t chunk,
                              std::vector<BlindCandidate>* found) const {
  // Onsets the flux missed (late impacts on top of ringing): starts where the NCC with the
  // template reaches template_threshold; runs closer than min_gap_s keep their best start.
  const std::size_t n = static_cast<std::size_t>(m.n);
  const std::size_t tl = static_cast<std::size_t>(template_len_);
  const std::size_t gap_s = static_cast<std::size_t>(options_.min_gap_s * rate_hz_);
  // The NCC of a template of L samples with white noise has a standard deviation of about
  // 1/sqrt(L): ask for 4 of those at least, so short templates (low rates) stay selective.
  const double ncc_min =
      std::max(options_.template_threshold, 4.0 / std::sqrt(static_cast<double>(tl)));
  const double k2 = ncc_min * ncc_min * m.hh;
  // The starts Refine's tight AIC window and TimeWithTemplate may read around a candidate
  // (TimingStarts of any time the window can give, with a margin); beyond them the chunks answer.
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long nw = window_;
  const long pre = std::max(nw, static_cast<long>(options_.aic_pre_s * rate_hz_));
  const long post = std::max(nw / 2, static_cast<long>(options_.aic_post_s * rate_hz_));
  const long before = std::max(16L, pre / 3) + 2 * maxlag + 8;
  const long after = std::max(8L, post / 2) + 2 * maxlag + 8;
  auto keep = [&](BlindCandidate* f) {
    const long i = static_cast<long>(f->start);
    chunks->Keep(std::max(0L, i - before), std::min(m.n - 1, i + after), &f->window);
  };
  const NccChunks::Chunk& c = chunks->Get(chunk);
  const std::size_t base = chunk * kNccChunk;
  const std::size_t i1 = std::min(base + kNccChunk, n > tl ? n - tl : 0);  // i + tl < n
  const float* xc = c.xc.data.get();
  const float* ww = c.ww.data.get();
  for (std::size_t i = std::max<std::size_t>(1, base); i < i1; ++i) {
    // NCC >= ncc_min <=> xc > 0 and xc^2 >= ncc_min^2 hh ww (no sqrt): most starts are not.
    i = base + NextNccCandidate(xc, ww, i - base, i1 - base, k2);
    if (i >= i1) break;
    const double c_i = xc[i - base];
    const double e = ww[i - base];
    const double ncc = e > 0.0 ? c_i / std::sqrt(m.hh * e) : 0.0;
    if (!found->empty() && i - found->back().start <= gap_s) {
      if (ncc > found->back().ncc) {
        found->back().start = i;
        found->back().ncc = ncc;
        keep(&found->back());
      }
      continue;
    }
    found->push_back({i, ncc, {}});
    keep(&found->back());
  }
}

void OnsetDetector::AddBlindCandidates(const std::vector<float>& x, const TemplateMatch& m,
                                       NccChunks* chunks, const std::vector<BlindCandidate>& found,
                                       OnsetResult* res) const {
  // Candidates away from the known onsets (timed by the template already) become onsets.
  std::vector<double> known;
  for (const Impact& im : res->onsets) known.push_back(im.time_s);
  std::sort(known.begin(), known.end());
  const std::size_t before = res->onsets.size();
  const std::size_t lead = static_cast<std::size_t>(m.lead);
  for (const BlindCandidate& f : found) {
    const double t = static_cast<double>(f.start + lead) / rate_hz_;
    auto it = std::lower_bound(known.begin(), known.end(), t);
    const bool near_known = (it != known.end() && *it - t < options_.min_gap_s) ||
                            (it != known.begin() && t - *(it - 1) < options_.min_gap_s);
    if (near_known) continue;
    Impact imp = Refine(x, *res, f.start + lead, true);
    imp.score = std::clamp(f.ncc, 0.0, 1.0);
    const long s0 = static_cast<long>(f.start);
    const NccWindow& v = f.window;
    const double hh = m.hh;
    auto ncc = [&](long l) {
      const long k = l - v.begin;
      if (k < 0 || k >= static_cast<long>(v.xc.size()))
        return chunks->Ncc(static_cast<std::size_t>(l));
      const double e = v.ww[static_cast<std::size_t>(k)];
      return e > 0.0 ? static_cast<double>(v.xc[static_cast<std::size_t>(k)]) / std::sqrt(hh * e)
                     : 0.0;
    };
    TimeWithTemplate(m, ncc, s0, s0, &imp);
    res->onsets.push_back(imp);
  }
  if (res->onsets.size() != before)
    std::sort(res->onsets.begin(), res->onsets.end(),
              [](const Impact& a, const Impact& b) { return a.time_s < b.time_s; });
}

void OnsetDetector::TemplatePass(const std::vector<float>& x, const std::vector<long>& window_lo,
                                 const std::vector<long>& window_hi, double template_onset_s,
                                 OnsetResult* res) const {
  // The impacts of one ball on one plate look alike: the whitened waveform of the strongest
  // onset is the template; its NCC with the whole whitened signal (FFT overlap-save) scores
  // every onset (Impact::score), times the clear matches and finds impacts the flux missed.
  // The NCC is computed chunk by chunk in time order (NccChunks); each onset is scored and
  // timed once the chunk holding the last start it reads is there, each chunk searched blind.
  if (res->onsets.empty()) return;
  TemplateMatch m;
  if (!BuildTemplate(res, template_onset_s, &m)) return;
  NccChunks chunks(*corr_, res->whitened, res->template_wave, m.hh, Threads());
  auto live = [&](long l) { return chunks.Ncc(static_cast<std::size_t>(l)); };
  const long n = m.n;
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  std::vector<Impact>& onsets = res->onsets;
  auto last_start = [&](std::size_t k) {
    const long s0 = std::lround(onsets[k].time_s * rate_hz_) - m.lead;
    return std::max(
        s0 + maxlag,
        TimingStarts(m, window_lo[k] - m.lead, window_hi[k] - m.lead, onsets[k].time_s).second);
  };
  auto score_and_time = [&](std::size_t k) {
    Impact& im = onsets[k];
    const long s0 = std::lround(im.time_s * rate_hz_) - m.lead;
    double best = 0.0;
    for (long l = std::max(0L, s0 - maxlag); l <= s0 + maxlag && l < n; ++l)
      best = std::max(best, live(l));
    im.score = std::clamp(best, 0.0, 1.0);
    TimeWithTemplate(m, live, window_lo[k] - m.lead, window_hi[k] - m.lead, &im);
  };
  const bool blind = options_.template_threshold < 1.0;
  std::vector<BlindCandidate> found;
  std::size_t next = 0;
  const std::size_t nchunks = (static_cast<std::size_t>(n) + kNccChunk - 1) / kNccChunk;
  for (std::size_t c = 0; c < nchunks; ++c) {
    const long chunk_end =
        static_cast<long>(std::min((c + 1) * kNccChunk, static_cast<std::size_t>(n)));
    for (; next < onsets.size() && last_start(next) < chunk_end; ++next) score_and_time(next);
    if (blind) BlindScan(m, &chunks, c, &found);
  }
  for (; next < onsets.size(); ++next) score_and_time(next);
  if (blind) AddBlindCandidates(x, m, &chunks, found, res);
}

MatchTemplate TemplateOf(const OnsetResult& r) {
  return MatchTemplate{r.template_wave, r.template_start, r.template_onset_s};
}

MatchTemplate TemplateAt(const OnsetResult& r, double onset_s) {
  MatchTemplate t;
  const long offset = r.template_start - std::lround(r.template_onset_s * r.rate_hz);
  const long start = std::lround(onset_s * r.rate_hz) + offset;
  const long len = static_cast<long>(r.template_wave.size());
  if (len == 0 || start < 0 || start + len > static_cast<long>(r.whitened.size())) return t;
  t.wave.assign(r.whitened.begin() + start, r.whitened.begin() + start + len);
  t.start = start;
  t.onset_s = onset_s;
  return t;
}

bool FindByTemplate(const OnsetResult& r, const MatchTemplate& tpl, const std::vector<float>& x,
                    double t_center_s, double half_window_s, double min_ncc, Impact* out,
                    double edge_penalty) {
  const std::vector<double>& h = tpl.wave;
  const std::vector<float>& w = r.whitened;
  if (h.empty() || !(r.rate_hz > 0.0) || w.size() != x.size()) return false;
  const long n = static_cast<long>(w.size()), tl = static_cast<long>(h.size());
  double hh = 0.0;
  for (double v : h) hh += v * v;
  if (!(hh > 0.0)) return false;
  // Template start l <-> onset t_ref + (l - template_start) / rate.
  auto start_of = [&](double t) { return tpl.start + std::lround((t - tpl.onset_s) * r.rate_hz); };
  const long lo = std::max(1L, start_of(t_center_s - half_window_s));
  const long hi = std::min(n - tl - 2, start_of(t_center_s + half_window_s));
  if (hi < lo) return false;
  auto ncc = [&](long l) {
    double xy = 0.0, yy = 0.0;
    for (long j = 0; j < tl; ++j) {
      const double y = w[static_cast<std::size_t>(l + j)];
      xy += h[static_cast<std::size_t>(j)] * y;
      yy += y * y;
    }
    return yy > 0.0 ? xy / std::sqrt(hh * yy) : 0.0;
  };
  long best_l = -1;
  double best_c = -2.0, best_rank = -1e300;
  const long l_centre = start_of(t_center_s);
  const double inv_half = half_window_s > 0.0 ? 1.0 / (half_window_s * r.rate_hz) : 0.0;
  for (long l = lo; l <= hi; ++l) {
    const double c = ncc(l);
    const double u = static_cast<double>(l - l_centre) * inv_half;
    const double rank = c - edge_penalty * u * u;
    if (rank > best_rank) {
      best_rank = rank;
      best_c = c;
      best_l = l;
    }
  }
  if (best_l < 1 || best_c < min_ncc) return false;
  const double cm = ncc(best_l - 1), cp = ncc(best_l + 1);
  const double curv = cm - 2.0 * best_c + cp;
  const double d = curv < 0.0 ? std::clamp(0.5 * (cm - cp) / curv, -0.5, 0.5) : 0.0;
  Impact imp;
  imp.time_s = tpl.onset_s + (static_cast<double>(best_l - tpl.start) + d) / r.rate_hz;
  const double sig_samples = 0.3 * std::sqrt(std::max(0.0, 1.0 - best_c * best_c)) / best_c;
  imp.sigma_s = std::hypot(sig_samples / r.rate_hz, r.sigma_floor_s);
  imp.score = std::clamp(best_c, 0.0, 1.0);
  const long i0 = std::clamp(std::lround(imp.time_s * r.rate_hz), 0L, n - 1);
  const long len_post = std::max(8L, static_cast<long>(0.0005 * r.rate_hz));
  const long len_pre = static_cast<long>(0.01 * r.rate_hz);
  double amp = 0.0, e_post = 0.0, e_pre = 0.0;
  long c_post = 0, c_pre = 0;
  for (long i = i0; i < std::min(n, i0 + static_cast<long>(0.003 * r.rate_hz) + 1); ++i)
    amp = std::max(amp, static_cast<double>(std::fabs(x[static_cast<std::size_t>(i)])));
  for (long i = i0; i < std::min(n, i0 + len_post); ++i, ++c_post)
    e_post += static_cast<double>(w[static_cast<std::size_t>(i)]) * w[static_cast<std::size_t>(i)];
  for (long i = std::max(0L, i0 - 2 - len_pre); i < i0 - 2; ++i, ++c_pre)
    e_pre += static_cast<double>(w[static_cast<std::size_t>(i)]) * w[static_cast<std::size_t>(i)];
  imp.amplitude = amp;
  const double floor_var = std::max(r.noise_rms * r.noise_rms, 1e-30);
  const double p_post = c_post ? e_post / static_cast<double>(c_post) : 0.0;
  const double p_pre = c_pre ? e_pre / static_cast<double>(c_pre) : floor_var;
  imp.snr_db = 10.0 * std::log10((p_post + 1e-30) / (std::max(p_pre, 1e-6 * floor_var) + 1e-30));
  *out = imp;
  return true;
}

double NccNoiseSpread(const OnsetResult& r, const MatchTemplate& tpl, double t0_s, double t1_s,
                      int max_positions) {
  const std::vector<double>& h = tpl.wave;
  const std::vector<float>& w = r.whitened;
  const long n = static_cast<long>(w.size()), tl = static_cast<long>(h.size());
  if (h.empty() || !(r.rate_hz > 0.0) || max_positions < 3) return 0.0;
  double hh = 0.0;
  for (double v : h) hh += v * v;
  auto start_of = [&](double t) { return tpl.start + std::lround((t - tpl.onset_s) * r.rate_hz); };
  const long lo = std::max(0L, start_of(t0_s)), hi = std::min(n - tl, start_of(t1_s));
  if (hi - lo < 3 || !(hh > 0.0)) return 0.0;
  const long step = std::max(1L, (hi - lo) / max_positions);
  std::vector<double> c;
  for (long l = lo; l < hi; l += step) {
    double xy = 0.0, yy = 0.0;
    for (long j = 0; j < tl; ++j) {
      const double y = w[static_cast<std::size_t>(l + j)];
      xy += h[static_cast<std::size_t>(j)] * y;
      yy += y * y;
    }
    c.push_back(yy > 0.0 ? xy / std::sqrt(hh * yy) : 0.0);
  }
  const auto mid = c.begin() + static_cast<std::ptrdiff_t>(c.size() / 2);
  std::nth_element(c.begin(), mid, c.end());
  const double med = *mid;
  for (double& v : c) v = std::fabs(v - med);
  std::nth_element(c.begin(), mid, c.end());
  return 1.4826 * *mid;
}

}  // namespace bouncecal

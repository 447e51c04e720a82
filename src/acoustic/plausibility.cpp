// Physical plausibility of tracked sequences. See include/bouncecal/acoustic/plausibility.hpp.
#include "bouncecal/acoustic/plausibility.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/stats.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double LevelDb(const Impact& i) { return 20.0 * std::log10(std::max(i.amplitude, 1e-12)); }

// Removes the members for which drop[k] is true (recorded in s->removed with `code`); a removal
// from inside the sequence leaves a gap of two flights, flagged in missed_after. Indices in
// missed_after / irregular_after are renumbered.
void RemoveMembers(Sequence* s, const std::vector<bool>& drop, const std::string& code) {
  std::vector<Impact> kept;
  std::vector<int> new_index(s->impacts.size(), -1);
  std::vector<int> missed, irregular;
  for (std::size_t k = 0; k < s->impacts.size(); ++k) {
    if (drop[k]) {
      s->removed.push_back({s->impacts[k], code});
      if (!kept.empty() && k + 1 < s->impacts.size())
        missed.push_back(static_cast<int>(kept.size()) - 1);
      continue;
    }
    new_index[k] = static_cast<int>(kept.size());
    kept.push_back(s->impacts[k]);
  }
  auto remap = [&](const std::vector<int>& v, std::vector<int>* out) {
    for (int k : v) {
      // Flag k (interval k -> k+1) survives when both ends survive.
      const std::size_t a = static_cast<std::size_t>(k), b = a + 1;
      if (b < new_index.size() && new_index[a] >= 0 && new_index[b] >= 0)
        out->push_back(new_index[a]);
    }
  };
  remap(s->missed_after, &missed);
  remap(s->irregular_after, &irregular);
  // A gap can only be flagged when the removed member had kept neighbours on both sides.
  std::vector<int> m2;
  for (int k : missed)
    if (k >= 0 && k + 1 < static_cast<int>(kept.size())) m2.push_back(k);
  std::sort(m2.begin(), m2.end());
  m2.erase(std::unique(m2.begin(), m2.end()), m2.end());
  s->impacts = std::move(kept);
  s->missed_after = std::move(m2);
  s->irregular_after = std::move(irregular);
  std::sort(s->removed.begin(), s->removed.end(),
            [](const RemovedImpact& a, const RemovedImpact& b) {
              return a.impact.time_s < b.impact.time_s;
            });
}

// A removal near the end that leaves fewer than two members after it leaves them no interval pair
// (an e needs two consecutive flights) and only the prediction across the gap to rest on: they go
// with it, and the last warning says so.
void DropDanglingTail(std::vector<bool>* drop, std::vector<Warning>* warnings) {
  const auto last = std::find(drop->rbegin(), drop->rend(), true);
  if (last == drop->rend() || warnings->empty()) return;
  const std::size_t k = static_cast<std::size_t>(drop->rend() - last) - 1;
  const std::size_t after = drop->size() - 1 - k;
  if (after == 0 || after >= 2) return;
  for (std::size_t j = k + 1; j < drop->size(); ++j) (*drop)[j] = true;
  warnings->back().message +=
      ", and so was the impact after it (no interval pair is left past the gap)";
}

}  // namespace

bool PlausibilityOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (min_snr_db && (!std::isfinite(*min_snr_db) || std::fabs(*min_snr_db) > 120.0))
    return fail("PlausibilityOptions::min_snr_db = " + FormatGeneral(*min_snr_db) +
                ": must be in [-120, 120] dB");
  if (!(max_sigma_fraction > 0.0) || max_sigma_fraction > 1.0)
    return fail("PlausibilityOptions::max_sigma_fraction = " + FormatGeneral(max_sigma_fraction) +
                ": must be in (0, 1]");
  if (!(level_tolerance_db > 0.0) || !std::isfinite(level_tolerance_db))
    return fail("PlausibilityOptions::level_tolerance_db must be a finite number > 0");
  if (!(sequence_level_tolerance_db > 0.0) || !std::isfinite(sequence_level_tolerance_db))
    return fail("PlausibilityOptions::sequence_level_tolerance_db must be a finite number > 0");
  if (level_reference_members < 1)
    return fail("PlausibilityOptions::level_reference_members must be >= 1");
  if (!(max_mean_ratio > 0.0) || max_mean_ratio > 1.05)
    return fail("PlausibilityOptions::max_mean_ratio = " + FormatGeneral(max_mean_ratio) +
                ": must be in (0, 1.05]");
  if (min_sequence_impacts < 3)
    return fail("PlausibilityOptions::min_sequence_impacts = " +
                std::to_string(min_sequence_impacts) + ": must be >= 3");
  return true;
}

double LevelAtUnitSpeedDb(const Sequence& s) {
  std::vector<double> c;
  for (std::size_t k = 1; k < s.impacts.size(); ++k) {
    const double t_prev = s.impacts[k].time_s - s.impacts[k - 1].time_s;
    if (t_prev > 0.0) c.push_back(LevelDb(s.impacts[k]) - 20.0 * std::log10(t_prev));
  }
  return Median(c);
}

double MeanIntervalRatio(const Sequence& s) {
  const auto& q = s.impacts;
  if (q.size() < 3) return kNaN;
  // Interval j (impacts j -> j + 1) is not one flight after a flagged gap, nor a regular one
  // after an irregular step: ratios that involve them say nothing about e.
  std::vector<bool> flagged(q.size(), false);
  for (int j : s.missed_after)
    if (j >= 0 && static_cast<std::size_t>(j) < q.size())
      flagged[static_cast<std::size_t>(j)] = true;
  for (int j : s.irregular_after)
    if (j >= 0 && static_cast<std::size_t>(j) < q.size())
      flagged[static_cast<std::size_t>(j)] = true;
  double sum = 0.0;
  int n = 0;
  for (std::size_t k = 2; k < q.size(); ++k) {
    if (flagged[k - 2] || flagged[k - 1]) continue;
    const double d0 = q[k - 1].time_s - q[k - 2].time_s, d1 = q[k].time_s - q[k - 1].time_s;
    if (!(d0 > 0.0) || !(d1 > 0.0)) continue;
    sum += std::log(d1 / d0);
    ++n;
  }
  return n > 0 ? std::exp(sum / n) : kNaN;
}

std::vector<Warning> RemoveUntimedMembers(Sequence* s, const PlausibilityOptions& o,
                                          const std::string& label) {
  std::vector<Warning> out;
  const auto& q = s->impacts;
  std::vector<bool> drop(q.size(), false);
  for (std::size_t k = 0; k < q.size(); ++k) {
    double shorter = std::numeric_limits<double>::infinity();
    if (k > 0) shorter = std::min(shorter, q[k].time_s - q[k - 1].time_s);
    if (k + 1 < q.size()) shorter = std::min(shorter, q[k + 1].time_s - q[k].time_s);
    const double sig = q[k].sigma_s;
    if (std::isfinite(sig) && sig > 0.0 && sig <= o.max_sigma_fraction * shorter) continue;
    drop[k] = true;
    out.push_back(
        {"sigma_removed",
         label + ": the impact at t = " + FormatFixed(q[k].time_s, 4) +
             " s was removed: its timing sigma (" + FormatGeneral(sig, 3) +
             " s) is not below max_sigma_fraction = " + FormatGeneral(o.max_sigma_fraction) +
             " of its shorter interval (" + FormatFixed(shorter, 4) + " s)",
         -1,
         "listen to what was kept (detect --click-track FILE.wav); if a bounce is "
         "missing, record closer to the impact point or in a quieter room"});
  }
  DropDanglingTail(&drop, &out);
  if (!out.empty()) RemoveMembers(s, drop, "sigma_removed");
  return out;
}

std::vector<Warning> RemoveLowSnrMembers(Sequence* s, const PlausibilityOptions& o,
                                         const std::string& label) {
  std::vector<Warning> out;
  if (!o.min_snr_db) return out;  // no cut (the default: detect.hpp says why)
  std::vector<bool> drop(s->impacts.size(), false);
  for (std::size_t k = 0; k < s->impacts.size(); ++k) {
    const Impact& i = s->impacts[k];
    if (i.snr_db >= *o.min_snr_db) continue;
    drop[k] = true;
    out.push_back({"low_snr_removed",
                   label + ": the impact at t = " + FormatFixed(i.time_s, 4) +
                       " s was removed: SNR " + FormatFixed(i.snr_db, 1) +
                       " dB is below min_snr_db = " + FormatGeneral(*o.min_snr_db) + " dB",
                   -1,
                   "to keep quieter impacts lower --min-snr-db (check them with detect "
                   "--click-track FILE.wav)"});
  }
  DropDanglingTail(&drop, &out);
  if (!out.empty()) RemoveMembers(s, drop, "low_snr_removed");
  return out;
}

std::vector<Warning> RemoveQuietEarlierMembers(Sequence* s, const PlausibilityOptions& o,
                                               const std::string& label) {
  std::vector<Warning> out;
  // Repeat until stable: a removed member no longer sets the reference of earlier ones.
  for (bool changed = true; changed;) {
    changed = false;
    const auto& q = s->impacts;
    std::vector<bool> drop(q.size(), false);
    for (std::size_t k = 0; k + 1 < q.size(); ++k) {
      std::vector<double> later;
      for (std::size_t j = k + 1;
           j < q.size() && later.size() < static_cast<std::size_t>(o.level_reference_members); ++j)
        later.push_back(LevelDb(q[j]));
      const double ref = Median(later);
      const double below = ref - LevelDb(q[k]);
      if (!(below > o.level_tolerance_db)) continue;
      drop[k] = true;
      out.push_back({"phantom_removed",
                     label + ": the impact at t = " + FormatFixed(q[k].time_s, 4) +
                         " s was removed: its level (" + FormatFixed(LevelDb(q[k]), 1) +
                         " dBFS) is " + FormatFixed(below, 1) +
                         " dB below the impacts after it, but an earlier impact is faster and "
                         "so not quieter (level_tolerance_db = " +
                         FormatGeneral(o.level_tolerance_db) + ")",
                     -1,
                     "nothing to do if it was a tap or a handling noise; if it was a bounce, "
                     "--start after the noise keeps it out of the search"});
    }
    if (std::find(drop.begin(), drop.end(), true) != drop.end()) {
      RemoveMembers(s, drop, "phantom_removed");
      changed = true;
    }
  }
  return out;
}

std::vector<Warning> EnforcePlausibility(std::vector<Sequence>* sequences,
                                         const PlausibilityOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  std::vector<Warning> out;
  auto append = [&](std::vector<Warning> w) { out.insert(out.end(), w.begin(), w.end()); };
  std::vector<Sequence>& seqs = *sequences;
  std::vector<std::string> labels;
  std::vector<bool> keep(seqs.size(), true);
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    labels.push_back(
        "the sequence from " +
        FormatFixed(seqs[s].impacts.empty() ? 0.0 : seqs[s].impacts.front().time_s, 4) + " s");
    append(RemoveUntimedMembers(&seqs[s], o, labels[s]));
    append(RemoveLowSnrMembers(&seqs[s], o, labels[s]));
    append(RemoveQuietEarlierMembers(&seqs[s], o, labels[s]));
    const double ratio = MeanIntervalRatio(seqs[s]);
    if (seqs[s].impacts.size() < static_cast<std::size_t>(o.min_sequence_impacts)) {
      keep[s] = false;
      if (!seqs[s].removed.empty())
        out.push_back({seqs[s].removed.back().code,
                       labels[s] + ": fewer than " + std::to_string(o.min_sequence_impacts) +
                           " impacts remain after the removals above: not a bounce sequence",
                       -1, "see the removals above; --start/--end around the drop"});
    } else if (!(ratio <= o.max_mean_ratio)) {
      keep[s] = false;
      out.push_back(
          {"not_shrinking",
           labels[s] + ": " + std::to_string(seqs[s].impacts.size()) +
               " impacts whose intervals do not shrink on average (mean ratio " +
               FormatFixed(ratio, 4) + " > max_mean_ratio = " + FormatGeneral(o.max_mean_ratio) +
               "): a metronome or repeated clicks, not a bouncing ball",
           -1, "nothing to do if these are not bounces; else --start/--end around the drop"});
    }
  }
  // One ball, one surface, one microphone: every sequence sounds as loud at the same impact speed.
  // The reference is the best-supported sequence (the largest sum of member weights, the
  // tracker's evidence, sequence.hpp), not the loudest: a chain of re-triggers inside a loud
  // impact's ringing takes that impact's level at the speed of millisecond flights, and would
  // outshine the ball. A sequence far quieter than the reference (handling taps) or far louder
  // (another impact's ringing, or another object) is not this ball.
  std::size_t ref = seqs.size();
  double ref_weight = -std::numeric_limits<double>::infinity();
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    if (!keep[s]) continue;
    double w = 0.0;
    for (const Impact& i : seqs[s].impacts) w += CandidateWeight(i);
    if (w > ref_weight) ref_weight = w, ref = s;
  }
  const double ref_level = ref < seqs.size() ? LevelAtUnitSpeedDb(seqs[ref]) : 0.0;
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    if (!keep[s] || s == ref) continue;
    const double below = ref_level - LevelAtUnitSpeedDb(seqs[s]);
    if (!(std::fabs(below) > o.sequence_level_tolerance_db)) continue;
    keep[s] = false;
    out.push_back({"phantom_removed",
                   labels[s] + ": " + std::to_string(seqs[s].impacts.size()) +
                       " impacts removed: at the same impact speed they are " +
                       FormatFixed(std::fabs(below), 1) + " dB " +
                       (below > 0.0 ? "quieter" : "louder") + " than " + labels[ref] +
                       " (the best-supported sequence of this recording), so they are not "
                       "this ball (sequence_level_tolerance_db = " +
                       FormatGeneral(o.sequence_level_tolerance_db) + ")",
                   -1,
                   below > 0.0
                       ? "nothing to do if another ball or object made them; to analyse them, "
                         "--start/--end around them"
                       : "nothing to do if they ring after a louder impact; to analyse them, "
                         "--start/--end around them"});
  }
  std::vector<Sequence> kept;
  for (std::size_t s = 0; s < seqs.size(); ++s)
    if (keep[s]) kept.push_back(std::move(seqs[s]));
  seqs = std::move(kept);
  return out;
}

}  // namespace bouncecal

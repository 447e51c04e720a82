// The detector on a growing recording (see include/bouncecal/acoustic/live.hpp): the batch
// detection of a trailing window, re-run as audio arrives, and the bookkeeping of what is final.
#include "bouncecal/acoustic/live.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal {

// One live sequence: what was reported, and the detector's latest view of it.
struct LiveDetector::Track {
  int id = 0;
  std::vector<Impact> reported;     // final members as last reported
  std::vector<Impact> latest;       // every member in the last run that found it
  std::int64_t missing_since = -1;  // frames fed when runs that found sequences stopped finding it
  double first_s() const {
    if (!latest.empty() && !reported.empty())
      return std::min(latest.front().time_s, reported.front().time_s);
    return latest.empty() ? reported.front().time_s : latest.front().time_s;
  }
};

namespace {

std::string Num(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

// Two detections of one impact: closer than half the shortest resolvable interval.
bool SameImpact(const Impact& a, const Impact& b, double tolerance_s) {
  return std::fabs(a.time_s - b.time_s) <= tolerance_s;
}

// Members of `found` that are also in `known` (by SameImpact).
int Shared(const std::vector<Impact>& found, const std::vector<Impact>& known, double tol) {
  int n = 0;
  for (const Impact& f : found)
    for (const Impact& k : known)
      if (SameImpact(f, k, tol)) {
        ++n;
        break;
      }
  return n;
}

}  // namespace

bool LiveOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& what) {
    if (error != nullptr) *error = "LiveOptions::" + what;
    return false;
  };
  if (!detect.IsValid(error)) return false;
  if (!(redetect_fraction > 0.0 && redetect_fraction <= 1.0))
    return fail("redetect_fraction " + Num("%g", redetect_fraction) + ": must be in (0, 1]");
  if (!(min_redetect_s > 0.0 && min_redetect_s <= max_redetect_s && max_redetect_s <= 10.0))
    return fail("min_redetect_s/max_redetect_s " + Num("%g", min_redetect_s) + "/" +
                Num("%g", max_redetect_s) + ": need 0 < min <= max <= 10 s");
  if (!(settle_s >= 0.0 && settle_s <= 10.0))
    return fail("settle_s " + Num("%g", settle_s) + ": must be in [0, 10] s");
  if (!(context_s >= 0.0 && context_s <= 10.0))
    return fail("context_s " + Num("%g", context_s) + ": must be in [0, 10] s");
  if (!(keep_quiet_s > settle_s && keep_quiet_s <= max_window_s))
    return fail("keep_quiet_s " + Num("%g", keep_quiet_s) +
                ": must be above settle_s and at most max_window_s");
  if (!(max_window_s > 0.0 && max_window_s <= detect.max_block_s))
    return fail("max_window_s " + Num("%g", max_window_s) +
                ": must be in (0, DetectOptions::max_block_s] (one block of the detector)");
  if (!(window_step_s > 0.0 && window_step_s < max_window_s))
    return fail("window_step_s " + Num("%g", window_step_s) + ": must be in (0, max_window_s)");
  if (!(forget_after_s >= 0.0 && forget_after_s <= 60.0))
    return fail("forget_after_s " + Num("%g", forget_after_s) + ": must be in [0, 60] s");
  if (!(revise_sigmas > 0.0 && std::isfinite(revise_sigmas)))
    return fail("revise_sigmas " + Num("%g", revise_sigmas) + ": must be > 0");
  if (!(revise_floor_samples >= 0.0 && std::isfinite(revise_floor_samples)))
    return fail("revise_floor_samples " + Num("%g", revise_floor_samples) + ": must be >= 0");
  return true;
}

LiveDetector::LiveDetector(double rate_hz, const LiveOptions& options, const std::string& name)
    : rate_hz_(rate_hz),
      options_(options),
      name_(name),
      max_flight_s_(TrackOptions{}.max_interval_s) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (!(rate_hz >= kMinSampleRateHz && rate_hz <= kMaxSampleRateHz) ||
      rate_hz != std::round(rate_hz))
    throw Error(ErrorCode::kBadParameter, name_ + ": sample rate " + Num("%g", rate_hz) +
                                              " Hz: expected a whole number of " + "hertz in [" +
                                              std::to_string(kMinSampleRateHz) + ", " +
                                              std::to_string(kMaxSampleRateHz) + "]");
}

LiveDetector::~LiveDetector() = default;

std::int64_t LiveDetector::window_frames() const {
  return static_cast<std::int64_t>(window_.size());
}

LiveUpdate LiveDetector::Feed(const float* samples, std::size_t count) {
  if (finished_) throw Error(ErrorCode::kUsage, name_ + ": samples after the end of the stream");
  for (std::size_t i = 0; i < count; ++i) {
    if (!(std::fabs(samples[i]) <= kMaxSampleMagnitude))
      throw Error(
          ErrorCode::kBadSamples,
          BadSampleMessage(name_, samples[i], 0, frames_ + static_cast<std::int64_t>(i), rate_hz_));
  }
  LiveUpdate update;
  std::size_t done = 0;
  // A large chunk is taken in steps, so that a caller that feeds seconds at once gets the same
  // runs (and the same window, bounded by max_window_s) as one that feeds it in small pieces.
  while (done < count) {
    const std::int64_t every = RunEvery();
    const auto room =
        static_cast<std::size_t>(std::max<std::int64_t>(1, last_run_ + every - frames_));
    const std::size_t n = std::min(room, count - done);
    window_.insert(window_.end(), samples + done, samples + done + n);
    frames_ += static_cast<std::int64_t>(n);
    done += n;
    if (frames_ - last_run_ >= every) Run(false, &update);
  }
  return update;
}

// The window the last run left (its length decides what the next run costs).
std::int64_t LiveDetector::RunEvery() const {
  const double held_s = static_cast<double>(last_run_ - start_) / rate_hz_;
  const double every_s = std::clamp(options_.redetect_fraction * held_s, options_.min_redetect_s,
                                    options_.max_redetect_s);
  return static_cast<std::int64_t>(std::ceil(every_s * rate_hz_));
}

LiveUpdate LiveDetector::Finish() {
  LiveUpdate update;
  if (finished_) return update;
  Run(true, &update);
  finished_ = true;
  return update;
}

void LiveDetector::Warn(const Warning& warning, LiveUpdate* update) {
  if (std::find(warned_.begin(), warned_.end(), warning.code) != warned_.end()) return;
  warned_.push_back(warning.code);
  update->warnings.push_back(warning);
  update->warnings.back().impact = -1;  // a window's index means nothing in the stream
}

// One detection run on the window: the batch detector, times moved to stream time; a window
// without a sequence (silent, nothing bouncing yet) is no sequence, not an error.
void LiveDetector::Run(bool final, LiveUpdate* update) {
  last_run_ = frames_;
  const double end_s = static_cast<double>(frames_) / rate_hz_;
  std::vector<Sequence> found;
  if (!window_.empty()) {
    Audio audio;
    audio.info.path = name_;
    audio.info.sample_rate_hz = rate_hz_;
    audio.info.channels = 1;
    audio.info.frames = static_cast<std::int64_t>(window_.size());
    audio.info.format = "stream";
    audio.info.subtype = "FLOAT";
    audio.channels.push_back(std::move(window_));  // lent to the run, taken back below
    audio.clipping.push_back(AnalyzeClipping(audio.channels[0], 0));
    DetectOptions o = options_.detect;
    o.channel = ChannelSelection{ChannelSelection::Kind::kIndex, 0};
    o.start_s = 0.0;
    o.end_s.reset();
    try {
      DetectionResult r = DetectImpacts(audio, o);
      found = std::move(r.sequences);
      for (const Warning& w : r.warnings)
        if (w.code == "clipped" || w.code == "detection_capped") Warn(w, update);
    } catch (const Error& e) {
      window_ = std::move(audio.channels[0]);
      if (e.code() != ErrorCode::kSilence && e.code() != ErrorCode::kNoBounces) throw;
    }
    if (window_.empty()) window_ = std::move(audio.channels[0]);
    ++detections_;
    ++update->detections;
    const double offset_s = static_cast<double>(start_) / rate_hz_;
    for (Sequence& q : found) {
      for (Impact& i : q.impacts) i.time_s += offset_s;
      for (RemovedImpact& r : q.removed) r.impact.time_s += offset_s;
    }
    // A sequence that starts in a closed one's stretch is that one, seen again.
    std::erase_if(found, [&](const Sequence& q) {
      return q.impacts.empty() || q.impacts.front().time_s <= frozen_until_s_;
    });
  }
  Update(std::move(found), final, update);
  Close(end_s, final, update);
  if (!final) Advance(end_s, update);
}

// Matches the sequences found to the open ones (most shared members first), then reports each
// matched sequence's newly final members, or revises it when what was reported changed.
void LiveDetector::Update(std::vector<Sequence> found, bool final, LiveUpdate* update) {
  const double tol = 0.5 * options_.detect.min_interval_s;
  const double horizon =
      final ? 1e300 : static_cast<double>(frames_) / rate_hz_ - options_.settle_s;
  std::vector<int> owner(found.size(), -1);  // index into open_
  std::vector<bool> taken(open_.size(), false);
  for (;;) {
    int best = 0, bf = -1, bt = -1;
    for (std::size_t f = 0; f < found.size(); ++f) {
      if (owner[f] >= 0) continue;
      for (std::size_t t = 0; t < open_.size(); ++t) {
        if (taken[t]) continue;
        const int n = std::max(Shared(found[f].impacts, open_[t].latest, tol),
                               Shared(found[f].impacts, open_[t].reported, tol));
        if (n > best) best = n, bf = static_cast<int>(f), bt = static_cast<int>(t);
      }
    }
    if (bf < 0) break;
    owner[static_cast<std::size_t>(bf)] = bt;
    taken[static_cast<std::size_t>(bt)] = true;
  }
  std::vector<Track> fresh;  // sequences seen for the first time
  for (std::size_t f = 0; f < found.size(); ++f) {
    Track* tr = nullptr;
    if (owner[f] >= 0) {
      tr = &open_[static_cast<std::size_t>(owner[f])];
    } else {
      tr = &fresh.emplace_back();
      tr->id = next_id_++;
    }
    tr->latest = found[f].impacts;
    std::vector<Impact> settled;
    for (const Impact& i : tr->latest)
      if (i.time_s <= horizon) settled.push_back(i);
    const std::size_t n = tr->reported.size();
    bool same = settled.size() >= n;
    std::string reason = "members changed";
    for (std::size_t k = 0; same && k < n; ++k) same = SameImpact(tr->reported[k], settled[k], tol);
    // Times carry the sequence's constant offset (timing.hpp), which moves with the template
    // and cancels in intervals: an interval that moved beyond its sigma is a revision.
    for (std::size_t k = 1; same && k < n; ++k) {
      const Impact &a0 = tr->reported[k - 1], &a1 = tr->reported[k];
      const Impact &b0 = settled[k - 1], &b1 = settled[k];
      const double moved = std::fabs((a1.time_s - a0.time_s) - (b1.time_s - b0.time_s));
      if (moved > options_.revise_floor_samples / rate_hz_ &&
          moved > options_.revise_sigmas * std::hypot(std::max(a0.sigma_s, b0.sigma_s),
                                                      std::max(a1.sigma_s, b1.sigma_s))) {
        same = false;
        reason = "intervals moved";
      }
    }
    if (!same) {
      tr->reported = settled;
      update->revisions.push_back({tr->id, settled, reason});
      continue;
    }
    for (std::size_t k = n; k < settled.size(); ++k) {
      tr->reported.push_back(settled[k]);
      update->impacts.push_back({tr->id, static_cast<int>(k), settled[k]});
    }
  }
  // Open sequences not found again by runs that found others: once that has lasted forget_after_s
  // (or at the end), no longer a sequence. A run that found nothing at all says nothing.
  const auto forget = static_cast<std::int64_t>(options_.forget_after_s * rate_hz_);
  std::vector<Track> kept;
  for (std::size_t t = 0; t < open_.size(); ++t) {
    Track& tr = open_[t];
    if (taken[t]) {
      tr.missing_since = -1;
    } else if (!found.empty()) {
      if (tr.missing_since < 0) tr.missing_since = frames_;
      if (final || frames_ - tr.missing_since >= forget) {
        if (!tr.reported.empty())
          update->revisions.push_back({tr.id, {}, "no longer a bounce sequence"});
        continue;
      }
    }
    kept.push_back(std::move(tr));
  }
  for (Track& tr : fresh) kept.push_back(std::move(tr));
  open_ = std::move(kept);
  std::sort(
      update->impacts.begin(), update->impacts.end(),
      [](const LiveImpact& a, const LiveImpact& b) { return a.impact.time_s < b.impact.time_s; });
}

// Closes the open sequences no further impact can join (all of them at the end of the stream).
void LiveDetector::Close(double end_s, bool final, LiveUpdate* update) {
  (void)update;
  std::vector<Track> still;
  for (Track& tr : open_) {
    const std::vector<Impact>& m = tr.latest.empty() ? tr.reported : tr.latest;
    const bool done =
        final || m.empty() || end_s - m.back().time_s > max_flight_s_ + options_.settle_s;
    if (!done) {
      still.push_back(std::move(tr));
      continue;
    }
    if (!m.empty()) frozen_until_s_ = std::max(frozen_until_s_, m.back().time_s);
    if (!tr.reported.empty()) closed_.push_back(std::move(tr));
  }
  open_ = std::move(still);
}

// Moves the window's start as far as the open sequences and a possible new drop allow.
void LiveDetector::Advance(double end_s, LiveUpdate* update) {
  double needed_s = end_s - options_.keep_quiet_s;
  for (const Track& tr : open_) needed_s = std::min(needed_s, tr.first_s() - options_.context_s);
  const double cap_s = end_s - options_.max_window_s + options_.window_step_s;
  if (needed_s < cap_s) {
    // The window would exceed max_window_s: the sequences it would cut are closed as they are.
    std::vector<Track> still;
    for (Track& tr : open_) {
      if (tr.first_s() - options_.context_s >= cap_s) {
        still.push_back(std::move(tr));
        continue;
      }
      Warn({"live_window_capped",
            name_ + ": a sequence lasted longer than the live window (" +
                Num("%g", options_.max_window_s) +
                " s): it was closed as it stood; the take's analysis has all of it",
            -1, "read the take's analysis at the end of the stream: it covers the whole sequence"},
           update);
      const std::vector<Impact>& m = tr.latest.empty() ? tr.reported : tr.latest;
      if (!m.empty()) frozen_until_s_ = std::max(frozen_until_s_, m.back().time_s);
      if (!tr.reported.empty()) closed_.push_back(std::move(tr));
    }
    open_ = std::move(still);
    needed_s = cap_s;
  }
  const auto needed = static_cast<std::int64_t>(std::floor(std::max(0.0, needed_s) * rate_hz_));
  const auto step = static_cast<std::int64_t>(std::ceil(options_.window_step_s * rate_hz_));
  if (needed - start_ < step) return;
  const std::int64_t drop = std::min<std::int64_t>(needed - start_, window_frames());
  window_.erase(window_.begin(), window_.begin() + static_cast<std::ptrdiff_t>(drop));
  start_ += drop;
}

std::vector<LiveImpact> LiveDetector::Impacts() const {
  std::vector<LiveImpact> out;
  auto add = [&](const Track& tr) {
    for (std::size_t k = 0; k < tr.reported.size(); ++k)
      out.push_back({tr.id, static_cast<int>(k), tr.reported[k]});
  };
  for (const Track& tr : closed_) add(tr);
  for (const Track& tr : open_) add(tr);
  std::sort(out.begin(), out.end(), [](const LiveImpact& a, const LiveImpact& b) {
    return a.sequence != b.sequence ? a.sequence < b.sequence : a.index < b.index;
  });
  return out;
}

Sequence LiveDetector::FinalSequence(int id) const {
  Sequence q;
  for (const std::vector<Track>* list : {&closed_, &open_})
    for (const Track& tr : *list)
      if (tr.id == id) q.impacts = tr.reported;
  return q;
}

}  // namespace bouncecal

// bouncecal/acoustic/live.hpp — the detector on a growing recording: impacts reported while the
// ball is still bouncing (the server's live sessions, `bouncecal listen`, Python's Listener).
//
// A streaming form of the same stages, not another detector: each run is the batch detection
// (DetectImpacts, detect.hpp) of a trailing window of the stream, re-run as audio arrives: after
// new audio of LiveOptions::redetect_fraction of the window's length. What the runs add is
// bookkeeping:
//   window   the window starts before the current drop (context_s before the first member of
//            every open sequence) or, with no sequence open, keep_quiet_s before the end: a drop
//            needs three impacts to be a sequence, its first flight may last up to
//            TrackOptions::max_interval_s, so two of those (and context) are kept; a closed
//            sequence is never detected again. The window is capped at max_window_s (the batch
//            detector's block length): memory stays bounded for a stream of any length;
//   final    a member is final once settle_s of audio follows it: timing is local
//            (timing.hpp: nothing depends on audio farther than TimingOptions::fit_after_s after
//            a member), and the onset stage needs a few hops past the onset;
//   revised  the tracker may still change a sequence as later impacts arrive (a member
//            removed, a missed impact found, the sequence dropped: after forget_after_s of
//            runs that found other sequences but not this one); an interval between final
//            members that moves by more than revise_sigmas of its sigma (and a quarter of a
//            sample) counts too (times
//            carry the sequence's constant offset, timing.hpp, which cancels in intervals). The
//            sequence's final members are then reported again, whole;
//   closed   a sequence is closed when no later impact can be chained with any of its members:
//            the tracker takes no flight longer than TrackOptions::max_interval_s, so once that
//            much audio (plus settle_s) follows its last member it is frozen, and the window
//            moves past it. (Closing sooner, after a few of its own intervals, froze a drop's
//            first impact with its ringing re-triggers before the second impact came.)
// Times are seconds from the first sample fed. Sequences have stable ids (0, 1, ... in the order
// they were first seen); an impact's index is its position among its sequence's final members.
//
//   LiveDetector live(48000.0, LiveOptions{});
//   while (n = ReadSomeSamples(buf)) {
//     for (const LiveImpact& i : live.Feed(buf, n).impacts) Print(i.sequence, i.index, i.impact);
//   }
//   LiveUpdate last = live.Finish();  // everything pending is final at the end of the stream
//
// The whole take's analysis is the batch detection of the whole take (the caller records it:
// audio_writer.hpp); the live results are what could be known while it was recorded.
// Common mistakes: one LiveDetector per stream, mono samples (mix channels first); Feed throws
// Error(kBadSamples) on a NaN/Inf or absurdly loud sample and the stream is then over.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"

namespace bouncecal {

struct LiveOptions {
  // The batch detection each run makes (channel, start_s and end_s are ignored: the stream is
  // mono and the window is the detector's).
  DetectOptions detect;
  // The next run comes after new audio of this fraction of the window's length (within
  // [min_redetect_s, max_redetect_s]). A run's cost grows with the window it detects, so this
  // holds a stream's CPU share steady: runs are frequent while the window is short (a drop's
  // first impacts) and sparser as it grows. 1/30: a 6.5 s window (no drop open) is detected
  // every 0.22 s, a 12 s one (a drop and the one before it) every 0.4 s; measured 6-8 % of a
  // core at 48 kHz (tools/bench_live, tools/bench_live.mjs), the median latency ~0.2 s.
  double redetect_fraction = 1.0 / 30.0;
  double min_redetect_s = 0.1;
  double max_redetect_s = 0.5;
  // Audio that must follow a member before it is final: twice TimingOptions::fit_after_s
  // (10 ms), the farthest the timing stage reads past a member. Measured on the bundled
  // recording and four synth presets: 20, 50 and 100 ms give the same reports.
  double settle_s = 0.02;
  // Audio kept before the first member of an open sequence (as the batch detector's blocks keep
  // 0.5 s around their cuts: whitening fit, running medians).
  double context_s = 0.5;
  // With no open sequence: audio kept before the end of the stream, 2 x
  // TrackOptions::max_interval_s + context_s (a drop's first two flights, see above).
  double keep_quiet_s = 6.5;
  // Longest window (the batch detector's block, DetectOptions::max_block_s): a sequence that
  // would need more is closed as it stands (warning live_window_capped).
  double max_window_s = 120.0;
  // The window start advances in steps of at least this much audio (fewer copies, and the
  // onset stage's whitening fit does not change with every run).
  double window_step_s = 1.0;
  // An interval between final members that moves by more than this many of its sigmas, and by
  // more than revise_floor_samples, is a revision.
  double revise_sigmas = 1.0;
  // Re-timed in a later window (another stretch of audio behind the template), an impact moves
  // by a fraction of a sample that sigma, the error independent from impact to impact, leaves
  // out: measured 0.1 sample (2.2 us, 5 sigma) on the bundled recording when its window grew;
  // exact copies are timed to 0.02 samples (timing_test). A quarter sample is no revision.
  double revise_floor_samples = 0.25;
  // A sequence the runs stop finding (while they find others) is dropped once this much audio
  // went by without it: a detection near the window's end can lose a weak sequence for a few
  // runs and find it again (the synthetic rubber ball's, for up to 0.5 s).
  double forget_after_s = 1.0;
  bool IsValid(std::string* error) const;
};

// A final impact of the stream.
struct LiveImpact {
  int sequence = 0;  // the live sequence's id
  int index = 0;     // position among that sequence's final members
  Impact impact;     // times from the stream's first sample
};

// A sequence whose final members changed after they were reported: `impacts` are all its final
// members now (empty: it is no longer a bounce sequence).
struct LiveRevision {
  int sequence = 0;
  std::vector<Impact> impacts;
  std::string reason;  // "members changed", "intervals moved", "no longer a bounce sequence"
};

// What one call changed.
struct LiveUpdate {
  std::vector<LiveRevision> revisions;  // first (their indices are the ones impacts follow)
  std::vector<LiveImpact> impacts;      // newly final, in time order
  std::vector<Warning> warnings;        // new warnings (each code once per stream)
  int detections = 0;                   // detection runs made by this call
};

class LiveDetector {
 public:
  // `name` names the stream in messages. Throws Error(kBadParameter) for invalid options or a
  // rate outside [kMinSampleRateHz, kMaxSampleRateHz].
  LiveDetector(double rate_hz, const LiveOptions& options = {},
               const std::string& name = "live stream");
  ~LiveDetector();
  LiveDetector(const LiveDetector&) = delete;
  LiveDetector& operator=(const LiveDetector&) = delete;

  // Appends mono samples and runs the detection each time the audio redetect_fraction asks for
  // has arrived (the runs depend on the samples only, not on how they are cut into calls). Throws
  // Error(kBadSamples) for a NaN/Inf sample or one beyond kMaxSampleMagnitude, Error(kUsage) after
  // Finish.
  LiveUpdate Feed(const float* samples, std::size_t count);
  LiveUpdate Feed(const std::vector<float>& samples) {
    return Feed(samples.data(), samples.size());
  }
  // The end of the stream: a last run on everything, every member final, every sequence closed.
  LiveUpdate Finish();

  double rate_hz() const { return rate_hz_; }
  std::int64_t frames() const { return frames_; }             // fed so far
  std::int64_t window_frames() const;                         // held now
  std::int64_t window_start_frame() const { return start_; }  // first frame held
  int detections() const { return detections_; }              // runs so far
  bool finished() const { return finished_; }
  // Every final impact reported so far (revisions applied), by sequence id then index.
  std::vector<LiveImpact> Impacts() const;
  // A live sequence's final members as a Sequence (for AnalyzeBounces); empty if unknown id.
  Sequence FinalSequence(int id) const;

 private:
  struct Track;
  void Run(bool final, LiveUpdate* update);
  void Update(std::vector<Sequence> found, bool final, LiveUpdate* update);
  void Close(double end_s, bool final, LiveUpdate* update);
  void Advance(double end_s, LiveUpdate* update);
  void Warn(const Warning& warning, LiveUpdate* update);  // once per code
  std::int64_t RunEvery() const;  // frames between runs for the window held now

  double rate_hz_;
  LiveOptions options_;
  std::string name_;
  double max_flight_s_;        // TrackOptions::max_interval_s: no chain steps further
  std::vector<float> window_;  // frames [start_, frames_)
  std::int64_t start_ = 0;
  std::int64_t frames_ = 0;
  std::int64_t last_run_ = 0;     // frames_ at the last run
  double frozen_until_s_ = -1.0;  // sequences starting at or before this are closed ones
  std::vector<Track> open_;
  std::vector<Track> closed_;
  std::vector<std::string> warned_;  // codes already reported
  int next_id_ = 0;
  int detections_ = 0;
  bool finished_ = false;
};

}  // namespace bouncecal

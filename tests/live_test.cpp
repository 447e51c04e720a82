// The detector on a growing recording (acoustic/live.hpp): what it reports while the stream runs
// agrees with the batch detector on the whole recording, as soon as the settle time allows, and
// its events rebuild its own state; its window, hence its memory, stays bounded; bad input is an
// Error. The bundled recording (data/default_steel_copper.flac, 74 impacts) and a synthetic
// drop (synth.hpp) are the streams.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {
namespace {

const std::string kFlac = std::string(BOUNCECAL_SOURCE_DIR) + "/data/default_steel_copper.flac";

const Audio& Bundled() {
  static const Audio a = ReadAudio(kFlac);
  return a;
}

// Everything a stream fed in chunks reported, and when (frames fed at the time).
struct Fed {
  std::vector<std::pair<LiveImpact, std::int64_t>> impacts;
  std::vector<LiveRevision> revisions;
  std::vector<Warning> warnings;
  std::vector<LiveImpact> final_state;
  std::int64_t max_window = 0;
  int detections = 0;
};

Fed FeedInChunks(const std::vector<float>& x, double rate, std::size_t chunk,
                 const LiveOptions& options = {}) {
  Fed out;
  LiveDetector live(rate, options);
  auto take = [&](const LiveUpdate& u) {
    for (const LiveImpact& i : u.impacts) out.impacts.push_back({i, live.frames()});
    out.revisions.insert(out.revisions.end(), u.revisions.begin(), u.revisions.end());
    out.warnings.insert(out.warnings.end(), u.warnings.begin(), u.warnings.end());
    out.max_window = std::max(out.max_window, live.window_frames());
  };
  for (std::size_t at = 0; at < x.size(); at += chunk)
    take(live.Feed(x.data() + at, std::min(chunk, x.size() - at)));
  take(live.Finish());
  out.final_state = live.Impacts();
  out.detections = live.detections();
  return out;
}

// The live sequence with the most final members, in order.
std::vector<Impact> LongestLiveSequence(const std::vector<LiveImpact>& all) {
  std::map<int, std::vector<Impact>> by;
  for (const LiveImpact& i : all) by[i.sequence].push_back(i.impact);
  std::vector<Impact> best;
  for (auto& [id, q] : by)
    if (q.size() > best.size()) best = q;
  return best;
}

// Intervals of `live` whose two ends match consecutive impacts of `batch` (within 1 ms) and
// whose length agrees within 3 combined sigmas (+1 us for the 24-bit rounding of a take):
// the fraction of batch's intervals so reproduced.
double ReproducedIntervals(const std::vector<Impact>& live, const std::vector<Impact>& batch,
                           double offset_s = 0.0) {
  int good = 0;
  for (std::size_t k = 0; k + 1 < batch.size(); ++k) {
    for (std::size_t j = 0; j + 1 < live.size(); ++j) {
      if (std::fabs(live[j].time_s + offset_s - batch[k].time_s) > 1e-3) continue;
      if (std::fabs(live[j + 1].time_s + offset_s - batch[k + 1].time_s) > 1e-3) break;
      const double a = live[j + 1].time_s - live[j].time_s;
      const double b = batch[k + 1].time_s - batch[k].time_s;
      const double s = std::hypot(batch[k].sigma_s, batch[k + 1].sigma_s);
      if (std::fabs(a - b) <= 3.0 * s + 1e-6) ++good;
      break;
    }
  }
  return batch.size() > 1 ? good / static_cast<double>(batch.size() - 1) : 0.0;
}

TEST(LiveDetector, IntervalsEqualTheBatchDetectorsOnTheBundledRecording) {
  const Audio& a = Bundled();
  const Fed fed = FeedInChunks(a.channels[0], a.info.sample_rate_hz, 2048);
  const DetectionResult batch = DetectImpacts(a, DetectOptions{});
  const std::vector<Impact> live = LongestLiveSequence(fed.final_state);
  ASSERT_EQ(batch.main().impacts.size(), 74u);  // README worked example
  EXPECT_GE(live.size(), 63u);
  EXPECT_GE(ReproducedIntervals(live, batch.main().impacts), 0.95);
  // Re-run at a bounded rate: at most one run per min_redetect_s of audio, and one at the end.
  const double duration_s = a.info.duration_s();
  EXPECT_LE(fed.detections, static_cast<int>(duration_s / LiveOptions{}.min_redetect_s) + 2);
}

// An impact is final once settle_s of audio follows it, and is then reported by the next run:
// never earlier, and (but for a sequence's first two impacts, which wait for the third) within
// a run's period of it.
TEST(LiveDetector, ImpactsAreReportedAsSoonAsTheirTimingIsFinal) {
  const Audio& a = Bundled();
  const double rate = a.info.sample_rate_hz;
  const LiveOptions o;
  const std::size_t chunk = 1024;
  const Fed fed = FeedInChunks(a.channels[0], rate, chunk, o);
  ASSERT_GT(fed.impacts.size(), 60u);
  int prompt = 0, late = 0;
  for (const auto& [i, frames] : fed.impacts) {
    const double fed_s = static_cast<double>(frames) / rate;
    if (frames == static_cast<std::int64_t>(a.channels[0].size())) continue;  // at Finish
    EXPECT_GE(fed_s, i.impact.time_s + o.settle_s) << "impact " << i.index;
    if (i.index < 2) continue;
    const double bound = i.impact.time_s + o.settle_s + o.max_redetect_s + chunk / rate;
    (fed_s <= bound ? prompt : late) += 1;
  }
  // Measured: every impact past the first two of the sequence (64 of 66 prompt, none late).
  std::printf("%zu impacts: %d prompt, %d late\n", fed.impacts.size(), prompt, late);
  EXPECT_GE(prompt, 60);
  EXPECT_LE(late, prompt / 20);
}

// A client that applies the messages (impacts appended, a revision replacing its sequence)
// ends with the detector's own final state.
TEST(LiveDetector, EventsRebuildTheFinalState) {
  SynthSpec spec = SynthPreset("pingpong-wood");
  spec.drops = {SynthDrop{1.0, std::nullopt}, SynthDrop{9.0, std::nullopt}};
  const Recording rec = Synthesize(spec).recording;
  LiveDetector live(rec.sample_rate_hz);
  std::map<int, std::vector<Impact>> client;
  int revisions = 0;
  auto apply = [&](const LiveUpdate& u) {
    for (const LiveRevision& r : u.revisions) {
      client[r.sequence] = r.impacts;
      ++revisions;
    }
    for (const LiveImpact& i : u.impacts) {
      std::vector<Impact>& q = client[i.sequence];
      ASSERT_EQ(static_cast<int>(q.size()), i.index) << "impacts arrive in order";
      q.push_back(i.impact);
    }
  };
  const std::vector<float>& x = rec.channels[0];
  for (std::size_t at = 0; at < x.size(); at += 4800)
    apply(live.Feed(x.data() + at, std::min<std::size_t>(4800, x.size() - at)));
  apply(live.Finish());
  std::map<int, std::vector<Impact>> state;
  for (const LiveImpact& i : live.Impacts()) state[i.sequence].push_back(i.impact);
  std::erase_if(client, [](const auto& kv) { return kv.second.empty(); });
  ASSERT_EQ(client.size(), state.size());
  for (const auto& [id, q] : state) {
    ASSERT_EQ(client[id].size(), q.size()) << "sequence " << id;
    for (std::size_t k = 0; k < q.size(); ++k) EXPECT_EQ(client[id][k].time_s, q[k].time_s);
  }
  EXPECT_GE(state.size(), 2u) << "two drops, two sequences";
  RecordProperty("revisions", revisions);
}

// The runs happen at the same amounts of audio whatever the chunks: the same events.
TEST(LiveDetector, ResultDoesNotDependOnTheChunkSize) {
  const Audio& a = Bundled();
  const double rate = a.info.sample_rate_hz;
  const std::vector<float> x(a.channels[0].begin(), a.channels[0].begin() + 4 * 48000);
  const Fed small = FeedInChunks(x, rate, 100);
  const Fed large = FeedInChunks(x, rate, 48000);
  ASSERT_EQ(small.final_state.size(), large.final_state.size());
  ASSERT_GT(small.final_state.size(), 5u);
  for (std::size_t k = 0; k < small.final_state.size(); ++k)
    EXPECT_EQ(small.final_state[k].impact.time_s, large.final_state[k].impact.time_s);
  EXPECT_EQ(small.detections, large.detections);
}

// Memory: with no sequence open the window holds keep_quiet_s (plus a step and a run's audio);
// a drop adds its own length; nothing grows with the stream. Two drops, then 40 s of noise.
TEST(LiveDetector, WindowStaysBoundedOnALongStream) {
  const Audio& a = Bundled();
  const double rate = a.info.sample_rate_hz;
  std::vector<float> x;
  for (int k = 0; k < 2; ++k) x.insert(x.end(), a.channels[0].begin(), a.channels[0].end());
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.0f, 3e-4f);
  for (int i = 0; i < 40 * 48000; ++i) x.push_back(noise(rng));
  LiveOptions o;
  LiveDetector live(rate, o);
  std::int64_t max_window = 0, max_window_last_minute = 0;
  for (std::size_t at = 0; at < x.size(); at += 4800) {
    live.Feed(x.data() + at, std::min<std::size_t>(4800, x.size() - at));
    max_window = std::max(max_window, live.window_frames());
    if (at > x.size() - 30 * 48000)
      max_window_last_minute = std::max(max_window_last_minute, live.window_frames());
  }
  live.Finish();
  // A drop of ~7.7 s plus context before it: well under twice the recording.
  EXPECT_LT(max_window, static_cast<std::int64_t>(2 * a.channels[0].size()));
  EXPECT_LE(
      max_window_last_minute,
      static_cast<std::int64_t>((o.keep_quiet_s + o.window_step_s + o.max_redetect_s) * rate) +
          4800);
  std::map<int, int> members;
  for (const LiveImpact& i : live.Impacts()) ++members[i.sequence];
  int full = 0;
  for (const auto& [id, n] : members) full += n >= 60 ? 1 : 0;
  EXPECT_EQ(full, 2) << "every drop found";
}

TEST(LiveDetector, BadInputIsAnError) {
  EXPECT_THROW(LiveDetector(1000.0), Error);
  EXPECT_THROW(LiveDetector(44100.5), Error);
  LiveOptions bad;
  bad.settle_s = -1.0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("settle_s"), std::string::npos);
  EXPECT_THROW(LiveDetector(48000.0, bad), Error);
  LiveDetector live(48000.0);
  std::vector<float> x(1000, 0.0f);
  x[500] = std::nanf("");
  try {
    live.Feed(x);
    FAIL() << "a NaN sample was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadSamples);
    EXPECT_NE(std::string(e.what()).find("frame 500"), std::string::npos) << e.what();
  }
  x[500] = 2e6f;
  EXPECT_THROW(live.Feed(x), Error);
  live.Finish();
  EXPECT_THROW(live.Feed(std::vector<float>(10, 0.0f)), Error);
}

TEST(LiveDetector, SilenceAndNoiseGiveNoImpacts) {
  std::vector<float> x(20 * 48000, 0.0f);
  std::mt19937 rng(1);
  std::normal_distribution<float> noise(0.0f, 1e-3f);
  for (std::size_t i = x.size() / 2; i < x.size(); ++i) x[i] = noise(rng);
  const Fed fed = FeedInChunks(x, 48000.0, 4800);
  EXPECT_TRUE(fed.final_state.empty());
  EXPECT_TRUE(fed.revisions.empty());
}

}  // namespace
}  // namespace bouncecal

// bouncecal/synth/realsound.hpp — test recordings made of REAL impact sounds at EXACT times.
//
// A second test-recording source beside synth.hpp that does not share its sound model: the
// sounds are cut from a real recording of a bouncing ball (NAME.wav with hand-marked onsets in
// NAME.impacts.csv, as in ../shared/recordings), the background is that room's noise
// (room_noise.hpp), and the times come from a physical bounce schedule (ImpactsFromRestitution:
// drop height, drag, e(v), per-bounce scatter). Truth is exact and the sounds are real.
//
//   SoundSource src = LoadSoundSource("../shared/recordings/eeps_pingpong.wav");
//   RealSoundSpec spec = RealSoundSpecFor(src);        // a schedule like the recording's
//   spec.drops.drops = 5;                              // five drops, 1.5 s of quiet between
//   RealSoundResult r = RenderRealSound(src, spec);
//   WriteAudio("x.wav", r.recording.channels, r.recording.sample_rate_hz);
//   WriteFileAtomically("x.truth.json", DumpJson(RealSoundTruthJson(src, spec, r), 2));
//
// 1. Cuts (LoadSoundSource). The candidates are the high-confidence (H) hand marks whose
//    previous impact's sound has decayed into the noise before the cut starts: the 10-ms RMS of
//    the recording just before the cut is at most 3 dB above the room's noise RMS, i.e. the
//    previous impact's residual carries no more power than the noise. A cut with more of the
//    previous sound in it would replay that residual every time it is placed, a second, false
//    sound source at a level the schedule does not control. Cuts whose peak reaches full scale
//    (>= 0.99: the recorder may have clipped between samples) are left out. The loudest
//    max_cuts candidates are cut from pre_s before the hand mark (the mark is +-0.2 ms; the
//    pre-roll holds only room noise and gets a raised-cosine fade-in) to where the sound's 10-ms
//    RMS falls to 3 dB above the noise (or to pre_s before the next marked impact), with a
//    raised-cosine fade-out.
// 2. One onset convention. The hand marks of one recording are refined to a common reference by
//    cross-correlating each cut's attack (attack_s from its mark, with 1 ms before) against the
//    loudest cut's, at sub-sample lags (windowed-sinc interpolation) within +-max_lag_s: each
//    cut's onset is its mark plus that lag, in the loudest cut's convention (its hand mark). The
//    residual alignment uncertainty is measured, not assumed: the lags of every pair of cuts
//    must close (lag(i,j) = lag(i) - lag(j)); alignment_sigma_s is the RMS closure error over
//    sqrt(3) (each closure sums three lag errors), unset with fewer than three cuts. With one cut
//    per drop (CutChoice::kOnePerDrop, the default) every interval is exact by construction,
//    whatever the alignment: the same sound is placed at every impact.
// 3. Placement. Each impact's sound is the cut, scaled by (v / v_cut)^amplitude_exponent (v the
//    impact speed, v_cut the speed of the impact the cut was taken from, from the marked
//    intervals: v = g dt_before / 2, the first impact's from the next interval and the ratio of
//    the next two, drag neglected), delayed to its onset with sub-sample precision by a
//    Kaiser-windowed sinc (32 taps each side, beta 8: flat within 0.01 dB to 0.8 x Nyquist).
//    Overlapping sounds add (the plate is linear). The time convention is synth's: sample n is
//    at n / rate; onset_s = time_s (no latency): the instant the cut's reference onset is heard.
// 4. Noise: fresh room noise (RoomNoise::Synthesize) over the whole file, never a copy.
// The cuts carry the room noise that was under them, scaled with them: a cut played louder than
// it was recorded brings its own noise up with it (up to the gain; keep the schedule's speeds
// near the recording's, as RealSoundSpecFor does).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/synth/room_noise.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {

// One row of NAME.impacts.csv (columns k, t_impact_s, confidence, ...).
struct HandMark {
  int k = 0;
  double time_s = 0.0;
  char confidence = 'L';  // 'H' (about +-0.2 ms), 'M' or 'L' (+-1-3 ms)
};
// Reads the marks (header line first). Throws Error(kInputMissing) for a missing file and
// Error(kBadScene) naming the file and line for a malformed one or fewer than 3 marks.
std::vector<HandMark> ReadHandMarks(const std::string& csv_path);

struct SoundSourceOptions {
  int max_cuts = 5;           // the loudest clean impacts kept (>= 1)
  double pre_s = 0.004;       // cut start before the hand mark (> fade_in_s + max_lag_s)
  double fade_in_s = 0.002;   // raised-cosine fade-in at the cut's start
  double fade_out_s = 0.010;  // raised-cosine fade-out at its end (at most a quarter of it)
  double attack_s = 0.005;    // attack compared when aligning cuts, after the mark
  double max_lag_s = 0.001;   // alignment search, +-: five times the marks' +-0.2 ms
  int channel = -1;           // the recording's channel; -1: the best (ImpactToNoiseDb)
  bool IsValid(std::string* error) const;
};

struct RealSoundCut {
  int mark = 0;                // index into SoundSource::marks
  double mark_s = 0.0;         // the hand mark, s in the recording
  double onset_s = 0.0;        // the refined onset (mark + lag), s in the recording
  double lag_s = 0.0;          // alignment lag against the reference cut
  double correlation = 1.0;    // normalised cross-correlation of the attacks at that lag
  double speed_m_s = 0.0;      // impact speed that made this sound
  double peak = 0.0;           // max |x| of the cut
  double start_s = 0.0;        // recording time of samples[0]
  double onset_index = 0.0;    // (onset_s - start_s) * rate: the onset in samples from [0]
  std::vector<float> samples;  // tapered
};

struct SoundSource {
  std::string path;  // the recording
  std::string name;  // its stem ("eeps_pingpong")
  double sample_rate_hz = 0.0;
  int channel = 0;
  std::vector<HandMark> marks;
  std::vector<RealSoundCut> cuts;  // loudest first; cuts[0] is the alignment reference
  std::optional<double> alignment_sigma_s;
  double noise_floor_rms = 0.0;  // 10-ms RMS of the quiet before the first impact (median)
  RoomNoise noise;
  // The recording's own schedule, from its H marks: median ratio of successive intervals, and
  // the drop height that gives its first interval with that e (vacuum, g = 9.81).
  double e_estimate = 0.0;
  double height_estimate_m = 0.0;
};

// Reads NAME.wav and NAME.impacts.csv, cuts, aligns and measures the noise. Throws Error
// (kInputMissing, kNotAudio, kBadScene for the marks, kBadParameter for invalid options or a
// recording without a clean H-marked impact or without quiet to measure its noise).
SoundSource LoadSoundSource(const std::string& wav_path, const SoundSourceOptions& options = {});

enum class CutChoice {
  kOnePerDrop,  // every impact of a drop plays the same cut (exact intervals by construction)
  kPerImpact,   // each impact plays a cut drawn at random (intervals exact to alignment_sigma_s)
};

struct RealSoundSpec {
  std::string name = "custom";
  Scene scene;  // ball, effects, drop height: the schedule's physics (sound-independent)
  RestitutionModel restitution = RestitutionModel::Constant(0.9);
  TruthOptions truth;  // min interval, scatter_e (its seed: scatter_seed)
  DropPlan drops;      // how many drops, gaps, identical copies or varied (synth.hpp)
  CutChoice cut_choice = CutChoice::kOnePerDrop;
  int cut = 0;                      // kOnePerDrop: the cut every drop plays; -1: one drawn per drop
  double amplitude_exponent = 1.0;  // sound amplitude ~ v^a (a = 1: momentum transfer)
  double noise_gain_db = 0.0;       // room noise this much louder (+) or quieter (-)
  bool noise = true;                // false: the clean sound alone (tests)
  double tail_s = 1.0;              // recording after the last onset
  // A window of the rendered file, [clip_start_s, clip_start_s + clip_length_s) (rounded to
  // whole samples), e.g. a short clip that starts in the middle of a sequence. The truth keeps
  // the impacts whose onset lies inside, on the clip's clock.
  std::optional<double> clip_start_s;
  std::optional<double> clip_length_s;
  std::uint64_t seed = 1;  // cut choices and noise
  bool IsValid(std::string* error) const;
};

// A schedule like the recording's own: its e estimate (constant), its height estimate, no drag
// unless the scene says so, the first impact at 0.5 s, one drop.
RealSoundSpec RealSoundSpecFor(const SoundSource& source);

struct RealSoundResult {
  Recording recording;  // one channel at the source's rate; drops[d][k] as synth's
  std::vector<std::vector<TruthImpact>> truth;
  std::vector<std::vector<int>> cut_of_impact;      // [drop][k] index into source.cuts
  std::vector<std::vector<double>> gain_of_impact;  // [drop][k] factor on the cut
  double output_gain = 1.0;    // everything scaled by this to keep the peak below full scale
  double clip_offset_s = 0.0;  // the clip's start on the full render's clock (0: no clip)
};

// Renders the spec's drops with the source's cuts and noise. Throws Error(kBadParameter) for an
// invalid spec or a schedule beyond max_duration.
RealSoundResult RenderRealSound(const SoundSource& source, const RealSoundSpec& spec);

// The truth document in the format of synth's TruthJson (LoadTruth reads it; every benchmark
// does): generator "bouncecal realsound <version>", drops[].impacts[] with time_s, onset_s,
// v_in_m_s, ..., plus "realsound": {recording, channel, cuts [{mark, mark_s, onset_s, lag_s,
// correlation, speed_m_s, peak, length_s}], alignment_sigma_s, onset_convention, cut_choice,
// noise (RoomNoise::ToJson), noise_gain_db, output_gain, clip} and per impact "cut", "gain".
nlohmann::json RealSoundTruthJson(const SoundSource& source, const RealSoundSpec& spec,
                                  const RealSoundResult& result);

}  // namespace bouncecal

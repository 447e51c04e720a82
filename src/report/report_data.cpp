// The adapter from result structs to the report object (see report_data.hpp).
#include "bouncecal/report/report_data.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

using nlohmann::json;

json Num(double v) { return std::isfinite(v) ? json(v) : json(); }
json Opt(const std::optional<double>& v) { return v ? Num(*v) : json(); }

// The channel the detector listened to (or would have): its samples for the waveform.
SelectedSignal ShownChannel(const Audio& audio, const ChannelSelection& selection,
                            const DetectionResult* detection) {
  ChannelSelection choice = selection;
  if (detection != nullptr) {
    choice = detection->channel >= 0
                 ? ChannelSelection{ChannelSelection::Kind::kIndex, detection->channel}
                 : ChannelSelection{ChannelSelection::Kind::kMix, 0};
  } else if (audio.channels.size() == 1) {
    choice = ChannelSelection{ChannelSelection::Kind::kIndex, 0};
  }
  return SelectChannel(audio, choice);
}

// Onsets of a recording in which no sequence was found: what the detector saw, for the marks.
std::vector<Impact> CandidatesWithoutSequence(const std::vector<float>& samples, double rate_hz,
                                              const DetectOptions& options) {
  OnsetOptions oo;
  oo.hop_s = options.hop_s;
  oo.lpc_order = options.lpc_order;
  const OnsetDetector detector(oo, rate_hz);
  return detector.Detect(samples).onsets;
}

// Where each impact of the main sequence sits, for warnings that name an impact.
double ImpactTime(const DetectionResult& d, int impact) {
  if (d.main_sequence < 0 || impact < 0) return std::numeric_limits<double>::quiet_NaN();
  const auto& imps = d.main().impacts;
  return impact < static_cast<int>(imps.size()) ? imps[static_cast<size_t>(impact)].time_s
                                                : std::numeric_limits<double>::quiet_NaN();
}

// Detected impacts of every sequence, and the candidates that are in none (rejected). A
// candidate belongs to a sequence when an impact lies within half the minimum resolvable
// interval of it (the tracker keeps candidates' times or re-times them by the template).
void ImpactsJson(const ReportRecording& r, json* out) {
  json impacts = json::array(), sequences = json::array(), rejected = json::array();
  std::vector<double> kept;
  if (r.detection) {
    const DetectionResult& d = *r.detection;
    for (size_t s = 0; s < d.sequences.size(); ++s) {
      const Sequence& q = d.sequences[s];
      sequences.push_back({{"index", s},
                           {"main", static_cast<int>(s) == d.main_sequence},
                           {"n_impacts", q.impacts.size()},
                           {"missed_after", q.missed_after},
                           {"end_reason", q.end_reason}});
      for (size_t k = 0; k < q.impacts.size(); ++k) {
        json j = ImpactJson(q.impacts[k]);
        j["sequence"] = s;
        j["index"] = k;
        impacts.push_back(j);
        kept.push_back(q.impacts[k].time_s);
      }
    }
  }
  std::sort(kept.begin(), kept.end());
  const double match_s = DetectOptions{}.min_interval_s / 2;
  for (const Impact& c : r.candidates) {
    const auto it = std::lower_bound(kept.begin(), kept.end(), c.time_s - match_s);
    if (it != kept.end() && *it <= c.time_s + match_s) continue;
    json j = ImpactJson(c);
    j["reason"] = r.detection ? "not part of a bounce sequence" : "no bounce sequence found";
    rejected.push_back(j);
  }
  (*out)["impacts"] = impacts;
  (*out)["sequences"] = sequences;
  (*out)["main_sequence"] =
      r.detection && r.detection->main_sequence >= 0 ? json(r.detection->main_sequence) : json();
  (*out)["rejected"] = rejected;
}

json BouncesJson(const Analysis& a) {
  json out = json::array();
  for (const Bounce& b : a.bounces) out.push_back(BounceJson(b));
  return out;
}

// Intervals t_{k+1} - t_k of the main sequence with sigma from the two onset sigmas
// (independent onsets: sigma^2 = sigma_k^2 + sigma_{k+1}^2).
json IntervalsJson(const DetectionResult& d) {
  json out = json::array();
  if (d.main_sequence < 0) return out;
  const auto& imps = d.main().impacts;
  for (size_t k = 0; k + 1 < imps.size(); ++k) {
    out.push_back({{"index", k},
                   {"interval_s", imps[k + 1].time_s - imps[k].time_s},
                   {"interval_sigma_s", Num(std::hypot(imps[k].sigma_s, imps[k + 1].sigma_s))}});
  }
  return out;
}

// Fit residuals of this recording. Trajectory: residual k is impact k of the main sequence
// (model - measured, s; sigma = the onset sigma that weighted it). Restitution: one per e point.
json ResidualsJson(const ReportRecording& r, const Calibration* c) {
  if (c == nullptr) return json();
  const RecordingFit* fit = nullptr;
  for (const RecordingFit& f : c->recordings)
    if (f.name == r.path) fit = &f;
  if (fit == nullptr) return json();
  const bool trajectory = c->strategy == FitStrategy::kTrajectory;
  const std::vector<Impact>* imps =
      r.detection && r.detection->main_sequence >= 0 ? &r.detection->main().impacts : nullptr;
  json values = json::array();
  for (size_t k = 0; k < fit->residuals.size(); ++k) {
    json v = {{"index", k}, {"residual", Num(fit->residuals[k])}, {"sigma", json()}};
    if (trajectory && imps != nullptr && imps->size() == fit->residuals.size()) {
      v["time_s"] = (*imps)[k].time_s;
      v["sigma"] = Num((*imps)[k].sigma_s);
    }
    values.push_back(v);
  }
  return {{"unit", c->residual_unit}, {"rms", Num(fit->rms_residual)}, {"values", values}};
}

json WarningsJson(const ReportRecording& r) {
  json out = json::array();
  auto add = [&](const Warning& w, const char* stage) {
    const double t = r.detection ? ImpactTime(*r.detection, w.impact) : NAN;
    out.push_back({{"code", w.code},
                   {"message", w.message},
                   {"impact", w.impact >= 0 ? json(w.impact) : json()},
                   {"time_s", Num(t)},
                   {"stage", stage},
                   {"hint", w.hint}});
  };
  if (r.detection)
    for (const Warning& w : r.detection->warnings) add(w, "detect");
  if (r.analysis)
    for (const Warning& w : r.analysis->warnings) add(w, "analyze");
  return out;
}

json RecordingJson(const ReportRecording& r, const Calibration* c,
                   const ReportDataOptions& options) {
  json j;
  j["file"] = r.path;
  j["sample_rate_hz"] = r.audio.sample_rate_hz;
  j["channels"] = r.audio.channels;
  j["channel"] = r.channel >= 0 ? json(r.channel) : json();  // null = the mix
  j["duration_s"] = r.audio.duration_s();
  j["format"] = r.audio.format + " " + r.audio.subtype;
  ImpactsJson(r, &j);
  std::vector<double> marks;
  for (const auto& i : j["impacts"]) marks.push_back(i["time_s"].get<double>());
  for (const auto& i : j["rejected"]) marks.push_back(i["time_s"].get<double>());
  std::sort(marks.begin(), marks.end());
  j["waveform"] = WaveformJson(r.samples, r.audio.sample_rate_hz, marks, options);
  j["no_impacts_reason"] = r.no_impacts_reason.empty() ? json() : json(r.no_impacts_reason);
  j["intervals"] = r.detection ? IntervalsJson(*r.detection) : json::array();
  j["bounces"] = r.analysis ? BouncesJson(*r.analysis) : json::array();
  j["summary"] = r.analysis
                     ? json{{"mean_eta_first3", Opt(r.analysis->mean_eta_first3)},
                            {"mean_eta_first3_sigma", Opt(r.analysis->mean_eta_first3_sigma)},
                            {"first_e", Opt(r.analysis->first_e)},
                            {"first_e_sigma", Opt(r.analysis->first_e_sigma)}}
                     : json();
  j["residuals"] = ResidualsJson(r, c);
  j["warnings"] = WarningsJson(r);
  return j;
}

// Energy ledger of the fitted law: the scene with the fitted parameters, started at the first
// recording's fitted first impact speed and time origin (trajectory fits), else at its first
// measured arrival speed (restitution fits), else at its drop; null when none is known.
json EnergyJson(const Calibration& c, const ReportRecording* first) {
  Scene scene = c.scene;
  auto start_at = [&](double v_m_s, double t_s) {
    scene.drop.height_m.reset();
    scene.drop.height_sigma_m.reset();
    scene.drop.impact_speed_m_s = v_m_s;
    scene.drop.first_impact_time_s = t_s;
  };
  if (!c.recordings.empty() && std::isfinite(c.recordings[0].impact_speed_m_s) &&
      c.recordings[0].impact_speed_m_s > 0) {
    start_at(c.recordings[0].impact_speed_m_s, c.recordings[0].time_origin_s);
  } else if (first != nullptr && first->analysis) {
    for (const Bounce& b : first->analysis->bounces) {
      if (std::isfinite(b.v_in_m_s) && b.v_in_m_s > 0) {
        start_at(b.v_in_m_s, b.time_s);
        break;
      }
    }
  }
  if (!scene.drop.height_m && !scene.drop.impact_speed_m_s) return json();
  const auto law = CreateLaw(scene.law, scene);
  const Simulation sim = Simulate(scene, *law, law->ParameterValues(), SimulatorOptions{});
  const double m = scene.ball.Mass();
  json impacts = json::array();
  for (size_t k = 0; k < sim.impacts.size(); ++k) {
    const SimImpact& i = sim.impacts[k];
    impacts.push_back({{"index", k},
                       {"time_s", i.time_s},
                       {"v_in_m_s", i.v_in_m_s},
                       {"v_out_m_s", i.v_out_m_s},
                       {"kinetic_in_j", 0.5 * m * i.v_in_m_s * i.v_in_m_s},
                       {"kinetic_out_j", 0.5 * m * i.v_out_m_s * i.v_out_m_s}});
  }
  const EnergyLedger& e = sim.energy;
  return {{"law", c.law},
          {"mass_kg", m},
          {"initial_j", e.initial_j},
          {"final_mechanical_j", e.final_mechanical_j},
          {"dissipated_contact_j", e.dissipated_contact_j},
          {"dissipated_drag_j", e.dissipated_drag_j},
          {"internal_j", e.internal_j},
          {"balance_error_j", e.balance_error_j},
          {"stop_reason", StopReasonName(sim.stop_reason)},
          {"stop_detail", sim.stop_detail},
          {"impacts", impacts}};
}

json EOfVJson(const std::vector<EOfVPoint>& points) {
  json out = json::array();
  for (const EOfVPoint& p : points)
    out.push_back({{"v_m_s", p.v_m_s}, {"e", Num(p.e)}, {"e_sigma", Num(p.sigma)}});
  return out;
}

json LawComparisonRowsJson(const std::vector<LawComparisonRow>& rows) {
  json out = json::array();
  int rank = 0;
  for (const LawComparisonRow& r : rows) {
    const Calibration& c = r.fit;
    const bool failed = c.outcome == FitOutcome::kFailed;
    out.push_back({{"rank", ++rank},
                   {"law", LawJson(c)},
                   {"outcome", FitOutcomeName(c.outcome)},
                   {"reason", c.reason},
                   {"hint", c.hint},
                   {"message", c.message},
                   {"delta_aic", failed ? json() : Num(r.delta_aic)},
                   {"aic", failed ? json() : Num(c.aic)},
                   {"chi2_dof", failed ? json() : Num(c.chi2_dof)},
                   {"rms_residual", failed ? json() : Num(c.rms_residual)},
                   {"residual_unit", c.residual_unit},
                   {"e_of_v", failed ? json::array() : EOfVJson(c.e_of_v)}});
  }
  return out;
}

json ProvenanceJson(const ReportInput& in) {
  json inputs = json::array();
  std::string version = BouncecalVersion(), date = NowIsoDateUtc();
  if (in.provenance) {
    for (const InputFile& f : in.provenance->inputs)
      inputs.push_back({{"file", f.path}, {"sha256", f.sha256}});
    version = in.provenance->bouncecal_version;
    date = in.provenance->date_utc;
  }
  return {{"inputs", inputs},
          {"bouncecal_version", version},
          {"options", in.options},
          {"date_utc", date},
          {"command", in.command.empty() ? json() : json(in.command)}};
}

}  // namespace

bool ReportDataOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (envelope_bins < 10 || envelope_bins > 1000000)
    return fail("ReportDataOptions::envelope_bins = " + std::to_string(envelope_bins) +
                ": must be 10..1000000");
  if (!(window_before_s >= 0 && window_after_s >= 0 && window_before_s + window_after_s < 1.0))
    return fail("ReportDataOptions::window_before_s/window_after_s must be >= 0, sum < 1 s");
  if (max_window_samples < 0) return fail("ReportDataOptions::max_window_samples must be >= 0");
  if (quantization_levels < 1 || quantization_levels > 1 << 24)
    return fail("ReportDataOptions::quantization_levels = " + std::to_string(quantization_levels) +
                ": must be 1..16777216");
  return true;
}

ReportRecording LoadReportRecording(const std::string& path, const DetectOptions& detect_options,
                                    const Scene& scene, const AnalysisOptions& analysis_options) {
  const Audio audio = ReadAudio(path);
  ReportRecording r;
  r.path = path;
  r.audio = audio.info;
  try {
    r.detection = DetectImpacts(audio, detect_options);
    r.candidates = r.detection->candidates;
  } catch (const Error& e) {
    if (e.code() != ErrorCode::kNoBounces && e.code() != ErrorCode::kSilence) throw;
    r.no_impacts_reason = e.what();
  }
  SelectedSignal shown =
      ShownChannel(audio, detect_options.channel, r.detection ? &*r.detection : nullptr);
  r.channel = shown.channel;
  r.samples = std::move(shown.samples);
  if (!r.detection) {
    if (r.no_impacts_reason.find("silent") == std::string::npos)
      r.candidates =
          CandidatesWithoutSequence(r.samples, audio.info.sample_rate_hz, detect_options);
    return r;
  }
  try {
    r.analysis = AnalyzeBounces(r.detection->main(), scene, analysis_options);
  } catch (const Error& e) {
    if (e.code() != ErrorCode::kNoBounces) throw;
    r.no_impacts_reason = path + ": " + e.what();
  }
  return r;
}

nlohmann::json WaveformJson(const std::vector<float>& samples, double rate_hz,
                            const std::vector<double>& times_s, const ReportDataOptions& options) {
  const long n = static_cast<long>(samples.size());
  double peak = 0.0;
  for (float v : samples) peak = std::max(peak, static_cast<double>(std::fabs(v)));
  const int levels = options.quantization_levels;
  const double scale = peak > 0 ? peak / levels : 1.0 / levels;
  auto q = [&](float v) { return static_cast<int>(std::lround(v / scale)); };

  // Envelope: bin b covers samples [b n / bins, (b + 1) n / bins).
  const long bins = std::max<long>(1, std::min<long>(options.envelope_bins, n));
  json mins = json::array(), maxs = json::array();
  for (long b = 0; b < bins && n > 0; ++b) {
    const long lo = b * n / bins, hi = std::max(lo + 1, (b + 1) * n / bins);
    const auto [mn, mx] = std::minmax_element(samples.begin() + lo, samples.begin() + hi);
    mins.push_back(q(*mn));
    maxs.push_back(q(*mx));
  }

  // Full-resolution windows around the marks, merged where they overlap.
  std::vector<std::pair<long, long>> spans;
  for (double t : times_s) {
    const long lo =
        std::max(0L, static_cast<long>(std::floor((t - options.window_before_s) * rate_hz)));
    const long hi =
        std::min(n, static_cast<long>(std::ceil((t + options.window_after_s) * rate_hz)));
    if (hi <= lo) continue;
    if (!spans.empty() && lo <= spans.back().second)
      spans.back().second = std::max(spans.back().second, hi);
    else
      spans.emplace_back(lo, hi);
  }
  json windows = json::array();
  long budget = options.max_window_samples, dropped = 0;
  for (const auto& [lo, hi] : spans) {
    if (hi - lo > budget) {
      ++dropped;
      continue;
    }
    budget -= hi - lo;
    json xs = json::array();
    for (long i = lo; i < hi; ++i) xs.push_back(q(samples[static_cast<size_t>(i)]));
    windows.push_back({{"start_s", static_cast<double>(lo) / rate_hz}, {"samples", xs}});
  }
  return {{"rate_hz", rate_hz},
          {"scale", scale},
          {"peak", peak},
          {"envelope",
           {{"bin_s", n > 0 ? static_cast<double>(n) / static_cast<double>(bins) / rate_hz : 0.0},
            {"min", mins},
            {"max", maxs}}},
          {"windows", windows},
          {"windows_dropped", dropped}};
}

nlohmann::json ReportDataJson(const ReportInput& input, const ReportDataOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  json j;
  j["schema"] = kReportSchema;
  json recs = json::array();
  for (const ReportRecording& r : input.recordings)
    recs.push_back(RecordingJson(r, input.calibration, options));
  j["recordings"] = recs;
  const Calibration* c = input.calibration;
  if (c != nullptr) {
    const Provenance prov =
        input.provenance.value_or(Provenance{{}, BouncecalVersion(), NowIsoDateUtc()});
    j["fit"] = CalibrationJson(*c, prov, input.options);
  } else {
    j["fit"] = json();
  }
  j["fit_failure"] = input.fit_failure.empty() ? json() : json(input.fit_failure);
  j["law_comparison"] =
      input.law_comparison ? LawComparisonRowsJson(*input.law_comparison) : json::array();
  j["energy"] = c != nullptr && c->outcome != FitOutcome::kFailed
                    ? EnergyJson(*c, input.recordings.empty() ? nullptr : &input.recordings.front())
                    : json();
  j["provenance"] = ProvenanceJson(input);
  return j;
}

}  // namespace bouncecal

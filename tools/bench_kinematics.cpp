// bench_kinematics — restitution accuracy of the whole acoustic half (detect + kinematics) on
// the rendered corpus, and what the exact flight model buys over interval ratios.
//
//   build/bench_kinematics              # 6 presets x 3 seeds
//   build/bench_kinematics --seeds 5
//
// For every synth preset (synth.hpp) and seed: render, write a 24-bit WAV, ReadAudio,
// DetectImpacts, then AnalyzeBounces of every detected sequence with the preset's own scene
// (drag, buoyancy, contact duration as rendered; the drop height only for a sequence whose first
// impact is the drop's first impact). Detected impacts are matched to the truth onsets within
// +-1 ms. A bounce k counts when impacts k-1, k, k+1 are matched to consecutive truth impacts.
// Columns:
//   n_e         bounces with e compared
//   rms_e       RMS(e - e_true), exact kinematics (this toolkit)
//   rms_e_ratio RMS(e - e_true) with e = dt_k / dt_{k-1} (seed 002 eq. 11: no drag, no contact
//               duration): the error that the flight model removes
//   max_e       max |e - e_true| (exact kinematics)
//   z_rms       RMS((e - e_true) / e_sigma): ~1 if the propagated sigmas are honest
//   rms_e_truth RMS(e - e_true) from the renderer's exact onsets (perfect detection): checks
//               the kinematics against the renderer's independent forward model
//   rms_ratio_truth  the same with interval ratios (no drag, no contact duration): the error
//               of the seed's eq. 11 alone, from perfect onsets
//   d_eta3      mean eta of the first three (exact kinematics) minus truth, per drop (mean |.|)
#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/synth/synth.hpp"

namespace fs = std::filesystem;
using namespace bouncecal;

namespace {

struct Row {
  int n_e = 0;
  double sum2 = 0, sum2_ratio = 0, max_abs = 0, z2 = 0;
  int n_eta3 = 0;
  double eta3_abs = 0;
  int files = 0, failed = 0;
  int n_truth = 0;
  double sum2_truth = 0, sum2_truth_ratio = 0;
};

struct Match {
  int drop = -1;
  int index = -1;
};

// Perfect detection (the truth onsets themselves): the kinematics alone against the truth.
void AddExactOnsetErrors(const SynthSpec& spec, const SynthResult& r, Row* row) {
  const auto& drops = r.recording.drops;
  // Perfect detection: the truth onsets themselves.
  for (size_t d = 0; d < drops.size(); ++d) {
    Sequence exact_seq;
    for (const RenderedImpact& ri : drops[d]) {
      Impact imp;
      imp.time_s = ri.onset_s;
      exact_seq.impacts.push_back(imp);
    }
    Scene scene = spec.scene;
    if (spec.drops[d].height_m) scene.drop.height_m = spec.drops[d].height_m;
    AnalysisOptions opt;
    if (spec.truth.contact_s) opt.contact_time_s = *spec.truth.contact_s;
    const Analysis a = AnalyzeBounces(exact_seq, scene, opt);
    Scene naive_scene = scene;
    naive_scene.effects = Effects{};
    const Analysis n = AnalyzeBounces(exact_seq, naive_scene, {});
    for (size_t k = 0; k + 1 < drops[d].size(); ++k) {
      const double err = a.bounces[k].e - drops[d][k].truth.e();
      ++row->n_truth;
      row->sum2_truth += err * err;
      const double err_ratio = n.bounces[k].e - drops[d][k].truth.e();
      row->sum2_truth_ratio += err_ratio * err_ratio;
    }
  }
}

// Detected sequences matched to the truth onsets (+-1 ms): e errors where a bounce's three
// impacts are consecutive truth impacts of one drop, and the mean eta of the first three.
void AddDetectedErrors(const SynthSpec& spec, const SynthResult& r, const DetectionResult& det,
                       const std::string& path, Row* row) {
  const auto& drops = r.recording.drops;
  for (const Sequence& seq : det.sequences) {
    // Match detected impacts to truth onsets (+-1 ms).
    std::vector<Match> m(seq.impacts.size());
    for (size_t k = 0; k < seq.impacts.size(); ++k) {
      double best = 1e-3;
      for (size_t d = 0; d < drops.size(); ++d) {
        for (size_t j = 0; j < drops[d].size(); ++j) {
          const double dt = std::abs(seq.impacts[k].time_s - drops[d][j].onset_s);
          if (dt < best) {
            best = dt;
            m[k] = {static_cast<int>(d), static_cast<int>(j)};
          }
        }
      }
    }
    if (m.empty() || m[0].drop < 0) continue;
    const int drop = m[0].drop;
    Scene scene = spec.scene;
    const SynthDrop& sd = spec.drops[static_cast<size_t>(drop)];
    if (sd.height_m) {
      scene.drop.height_m = sd.height_m;
      scene.drop.impact_speed_m_s.reset();
    }
    AnalysisOptions exact_opt;
    exact_opt.use_drop = m[0].index == 0;
    if (spec.truth.contact_s) exact_opt.contact_time_s = *spec.truth.contact_s;
    Scene naive = scene;
    naive.effects = Effects{};
    AnalysisOptions naive_opt;
    naive_opt.use_drop = exact_opt.use_drop;
    Analysis exact, ratio;
    try {
      exact = AnalyzeBounces(seq, scene, exact_opt);
      ratio = AnalyzeBounces(seq, naive, naive_opt);
    } catch (const Error& e) {
      std::fprintf(stderr, "%s: %s\n", path.c_str(), e.what());
      continue;
    }
    const auto& truth = drops[static_cast<size_t>(drop)];
    for (size_t k = 0; k + 1 < seq.impacts.size(); ++k) {
      const Bounce& b = exact.bounces[k];
      if (!std::isfinite(b.e)) continue;
      const bool prev_ok =
          k == 0 ? (m[0].index == 0) : (m[k - 1].drop == drop && m[k].index == m[k - 1].index + 1);
      const bool next_ok = m[k + 1].drop == drop && m[k + 1].index == m[k].index + 1;
      if (m[k].drop != drop || !prev_ok || !next_ok) continue;
      const double e_true = truth[static_cast<size_t>(m[k].index)].truth.e();
      const double err = b.e - e_true;
      const double err_ratio = ratio.bounces[k].e - e_true;
      ++row->n_e;
      row->sum2 += err * err;
      row->sum2_ratio += err_ratio * err_ratio;
      row->max_abs = std::max(row->max_abs, std::abs(err));
      if (b.e_sigma > 0) row->z2 += (err / b.e_sigma) * (err / b.e_sigma);
    }
    if (exact.mean_eta_first3) {
      double eta_true = 0;
      bool ok = true;
      for (int k : exact.mean_eta_indices) {
        const Match& mk = m[static_cast<size_t>(k)];
        if (mk.drop != drop) ok = false;
        if (ok) eta_true += 1 - std::pow(truth[static_cast<size_t>(mk.index)].truth.e(), 2);
      }
      if (ok) {
        ++row->n_eta3;
        row->eta3_abs += std::abs(*exact.mean_eta_first3 - eta_true / 3);
      }
    }
  }
}

void PrintRow(const std::string& label, const Row& rw) {
  const double n = std::max(rw.n_e, 1);
  std::printf(
      "%-14s %5d %5d %11.3e %11.3e %9.2e %6.2f %9.2e %11.3e %15.3e%s\n", label.c_str(), rw.files,
      rw.n_e, std::sqrt(rw.sum2 / n), std::sqrt(rw.sum2_ratio / n), rw.max_abs,
      std::sqrt(rw.z2 / n), rw.n_eta3 ? rw.eta3_abs / rw.n_eta3 : NAN,
      std::sqrt(rw.sum2_truth / std::max(rw.n_truth, 1)),
      std::sqrt(rw.sum2_truth_ratio / std::max(rw.n_truth, 1)),
      rw.failed ? (" (detection failed on " + std::to_string(rw.failed) + ")").c_str() : "");
}

void Accumulate(const Row& row, Row* total) {
  total->files += row.files;
  total->failed += row.failed;
  total->n_e += row.n_e;
  total->sum2 += row.sum2;
  total->sum2_ratio += row.sum2_ratio;
  total->max_abs = std::max(total->max_abs, row.max_abs);
  total->z2 += row.z2;
  total->n_eta3 += row.n_eta3;
  total->eta3_abs += row.eta3_abs;
  total->n_truth += row.n_truth;
  total->sum2_truth += row.sum2_truth;
  total->sum2_truth_ratio += row.sum2_truth_ratio;
}

}  // namespace

int main(int argc, char** argv) {
  int seeds = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--seeds" && i + 1 < argc) {
      seeds = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_kinematics [--seeds N]\n");
      return 2;
    }
  }
  const fs::path dir = fs::temp_directory_path() / ("bench_kinematics_" + std::to_string(getpid()));
  fs::create_directories(dir);
  std::printf("%-14s %5s %5s %11s %11s %9s %6s %9s %11s %15s\n", "preset", "files", "n_e", "rms_e",
              "rms_e_ratio", "max_e", "z_rms", "d_eta3", "rms_e_truth", "rms_ratio_truth");
  Row total;
  for (const std::string& name : SynthPresetNames()) {
    Row row;
    for (int seed = 1; seed <= seeds; ++seed) {
      SynthSpec spec = SynthPreset(name);
      spec.render.seed = static_cast<std::uint64_t>(seed);
      const SynthResult r = Synthesize(spec);
      const std::string path = (dir / (name + "-" + std::to_string(seed) + ".wav")).string();
      WriteAudio(path, r.recording.channels, r.recording.sample_rate_hz, {"PCM_24"});
      ++row.files;
      AddExactOnsetErrors(spec, r, &row);
      DetectionResult det;
      try {
        det = DetectImpacts(ReadAudio(path), DetectOptions{});
      } catch (const Error& e) {
        std::fprintf(stderr, "%s: %s\n", path.c_str(), e.what());
        ++row.failed;
        continue;
      }
      AddDetectedErrors(spec, r, det, path, &row);
    }
    PrintRow(name, row);
    Accumulate(row, &total);
  }
  std::printf("%-14s %5d %5d %11.3e %11.3e %9.2e %6.2f %9.2e %11.3e %15.3e\n", "all", total.files,
              total.n_e, std::sqrt(total.sum2 / std::max(total.n_e, 1)),
              std::sqrt(total.sum2_ratio / std::max(total.n_e, 1)), total.max_abs,
              std::sqrt(total.z2 / std::max(total.n_e, 1)),
              total.n_eta3 ? total.eta3_abs / total.n_eta3 : NAN,
              std::sqrt(total.sum2_truth / std::max(total.n_truth, 1)),
              std::sqrt(total.sum2_truth_ratio / std::max(total.n_truth, 1)));
  std::error_code ec;
  fs::remove_all(dir, ec);
  return 0;
}

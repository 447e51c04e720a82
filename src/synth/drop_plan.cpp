// Several drops in one file: where each drop starts and how it differs (see DropPlan in
// include/bouncecal/synth/synth.hpp).
#include <cmath>
#include <sstream>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/synth/synth.hpp"
#include "random.hpp"

namespace bouncecal {
namespace {

using synth_random::Rng;
using synth_random::Stream;

// The plan's random stream (apart from the renderer's noise, hum, ... streams of synth.cpp).
constexpr std::uint64_t kDropPlanPurpose = 6;

bool Finite(double v) { return std::isfinite(v); }

}  // namespace

bool DropPlan::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "drop plan: " + m;
    return false;
  };
  if (drops < 1 || drops > kMaxDrops)
    return fail("drops = " + std::to_string(drops) + " (expected 1 to " +
                std::to_string(kMaxDrops) + ")");
  if (!(first_impact_s >= 0.0 && Finite(first_impact_s)))
    return fail("first_impact_s = " + FormatGeneral(first_impact_s, 10) + " (expected >= 0)");
  if (!(gap_min_s >= 0.0 && Finite(gap_min_s)))
    return fail("gap_min_s = " + FormatGeneral(gap_min_s, 10) + " (expected >= 0)");
  if (!(gap_max_s >= gap_min_s && Finite(gap_max_s)))
    return fail("gap_max_s = " + FormatGeneral(gap_max_s, 10) +
                " (expected >= gap_min_s = " + FormatGeneral(gap_min_s, 10) + ")");
  if (!(height_spread >= 0.0 && height_spread < 1.0))
    return fail("height_spread = " + FormatGeneral(height_spread, 10) +
                " (expected 0 <= spread < 1)");
  if (!(e_spread >= 0.0 && e_spread < 0.5))
    return fail("e_spread = " + FormatGeneral(e_spread, 10) + " (expected 0 <= spread < 0.5)");
  return true;
}

std::vector<SynthDrop> PlanDrops(const SynthSpec& spec, const DropPlan& plan) {
  std::string err;
  if (!plan.IsValid(&err)) throw Error(ErrorCode::kBadParameter, err);
  if (plan.e_spread > 0.0 && spec.truth_source == TruthSource::kLaw)
    throw Error(ErrorCode::kBadParameter,
                "drop plan: e_spread needs restitution truth (the contact law sets e)");
  const std::optional<double> base_height =
      spec.drops.empty() ? std::nullopt : spec.drops.front().height_m;
  Rng gaps = Stream(plan.seed, kDropPlanPurpose, 0);
  Rng vary = Stream(plan.seed, kDropPlanPurpose, 1);
  std::vector<SynthDrop> out;
  double t = plan.first_impact_s;
  for (int i = 0; i < plan.drops; ++i) {
    SynthDrop d{t, base_height};
    if (plan.varied()) {
      const double h = base_height.value_or(spec.scene.drop.height_m.value_or(0.0));
      if (plan.height_spread > 0.0 && h > 0.0)
        d.height_m = h * vary.Uniform(1.0 - plan.height_spread, 1.0 + plan.height_spread);
      if (plan.e_spread > 0.0) d.e_shift = vary.Uniform(-plan.e_spread, plan.e_spread);
      d.scatter_seed = spec.truth.scatter_seed + 1000003ull * static_cast<std::uint64_t>(i + 1);
    }
    const std::vector<TruthImpact> truth = DropTruth(spec, d);
    out.push_back(d);
    t = truth.back().time_s + gaps.Uniform(plan.gap_min_s, plan.gap_max_s);
  }
  return out;
}

}  // namespace bouncecal

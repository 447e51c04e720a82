// A parameter file holding a real fit, for the export suites: `law` fitted (trajectory
// strategy) to 12 impacts simulated with `truth`, written as a parameter file.
#pragma once

#include <map>
#include <string>

#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "test_util.hpp"

namespace bouncecal::testing_util {

inline std::string WriteFit(const ScratchDir& dir, const std::string& law,
                            const std::map<std::string, double>& truth, const std::string& name) {
  Scene s;
  s.law = {law, truth, ""};
  s.limits.max_impacts = 12;
  auto l = CreateLaw(s.law, s);
  const Simulation sim = Simulate(s, *l, l->ParameterValues());
  Sequence seq;
  for (const auto& i : sim.impacts) seq.impacts.push_back({1.0 + i.time_s, 5e-6});
  Scene start;
  start.law.name = law;
  CalibrationOptions o;
  o.strategy = FitStrategy::kTrajectory;  // simulated times: the contacts are in the intervals
  const Calibration c = Calibrate({{"drop.wav", seq}}, start, o);
  Provenance prov;
  prov.bouncecal_version = "test";
  prov.date_utc = "2026-01-01T00:00:00Z";
  const std::string path = dir / name;
  WriteParamFile(path, CalibrationJson(c, prov, OptionsJson(CalibrationOptions{})), {});
  return path;
}

}  // namespace bouncecal::testing_util

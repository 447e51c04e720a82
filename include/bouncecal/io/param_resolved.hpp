// bouncecal/io/param_resolved.hpp — the parameter file as a complete input (issue 12).
//
// A parameter file names the fitted law and the scene it was fitted in; material presets
// ("steel", "copper") leave E and nu implicit and a DEM code needs numbers. The "resolved"
// section holds every physical value a simulator needs, as numbers in SI units:
//
//   "resolved": {
//     "ball":    {"diameter_m", "radius_m", "mass_kg", "density_kg_m3", "youngs_modulus_pa",
//                 "poisson_ratio"},
//     "surface": {"kind", "youngs_modulus_pa", "poisson_ratio"},
//     "contact": {"effective_mass_kg", "effective_radius_m", "effective_modulus_pa",
//                 "contact_end"},                        // m* = m, R* = R on a rigid wall
//     "environment": {"g_m_s2"},
//     "drop":    {"impact_speed_m_s", "release_height_m", "from"},   // what a replay starts from
//     "contacts": [{"v_m_s", "e", "contact_time_s", "peak_overlap_m"}]}  // at the measured speeds
//
// E* = 1 / ((1 - nu_b^2)/E_b + (1 - nu_s^2)/E_s) (Johnson, Contact Mechanics, eq. 4.22); null
// where a material has no elastic constants. release_height_m is the drag-free height of the
// ball's bottom that gives impact_speed_m_s (v^2 / 2g). "from" says where the drop comes from:
// "recording 0 fit" (a trajectory fit's first impact speed of the first recording) or "scene".
//
// Reading back: ReplayFromParamFile builds the Scene that replays the fit — the file's scene
// (scene_toml), with the resolved ball and surface constants written in as explicit values (so
// a later change of a preset table cannot change the replay), the fitted law parameters and the
// replay drop. When the file carries a "resolved" section its values are checked against the
// scene; a disagreement is Error(kBadParameter) naming the key.
//
//   ParamFile pf = ReadParamFile("params.json");
//   Replay r = ReplayFromParamFile(pf);
//   auto law = CreateLaw(r.scene.law, r.scene);
//   Simulation sim = Simulate(r.scene, *law, law->ParameterValues());
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/io/param_file.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

// The "resolved" object for a scene whose law carries the fitted parameters. speeds_m_s are the
// speeds at which contacts are tabulated (the measured range: the e_of_v speeds).
// replay_impact_speed_m_s > 0 replaces the scene's drop (a trajectory fit's first impact speed).
nlohmann::json ResolvedJson(const Scene& scene, const std::vector<double>& speeds_m_s,
                            double replay_impact_speed_m_s = 0.0);
// ResolvedJson for a calibration: the e_of_v speeds and the first recording's fitted speed.
nlohmann::json ResolvedJson(const Calibration& calibration);

struct Replay {
  Scene scene;                     // law with parameters, drop, every constant explicit
  std::vector<double> speeds_m_s;  // the measured speed range (e_of_v speeds); may be empty
  double v_min_m_s = 0.0;          // measured impact speeds (fit.v_min/v_max), 0 if absent
  double v_max_m_s = 0.0;
  std::string drop_from;  // "recording 0 fit" or "scene"
};

// Throws Error(kBadParameter) naming the file and key for a missing or unreadable scene, a
// resolved value that disagrees with the scene, or law parameters the law rejects.
Replay ReplayFromParamFile(const ParamFile& file, const std::string& path);

}  // namespace bouncecal

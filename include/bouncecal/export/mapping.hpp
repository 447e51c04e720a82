// bouncecal/export/mapping.hpp — which native law of a DEM simulator carries a fitted law, with
// which coefficients, and how far its restitution is from the fit.
//
// For each bouncecal law and target simulator the mapping picks the simulator's native law
// (native_law.hpp) and its coefficients:
//  - exact: the simulator evaluates the same force law (linear-dashpot -> LAMMPS `hooke` with
//    `damping velocity`; hertz-viscoelastic -> LAMMPS `damping viscoelastic`, LIGGGHTS
//    `hertz/stiffness`; hertz-tsuji -> LAMMPS `damping tsuji`, LIGGGHTS `hertz`);
//  - matched: a different native law whose e and contact time equal the fit's at every speed
//    (constant-e laws: walton-braun -> a linear spring-dashpot with the same e and t_c;
//    Yade's force clipping compensated by a damping solved under the F = 0 end);
//  - approximated: a constant-e native law closest to the fitted e(v) over the measured speeds
//    (hertz-viscoelastic in Yade, the Hunt-Crossley and Jiang-Liu laws everywhere); max_e_error
//    is then half the spread of e(v) over those speeds (or what the mapping leaves).
// Known slips of the installed versions are compensated in the coefficients (LAMMPS' Tsuji
// alpha(e) polynomial, Yade's series combination of material stiffnesses and its wall radius
// convention) and stated in notes. max_e_error is measured, not assumed: the native model's
// e(v) (bouncecal's integrator) against the fitted law's at every speed.
//
//   Mapping m = MapLaw(replay_scene, speeds, ExportTarget::kLammps);
//   if (m.max_e_error > 0.01 && !allow) ...refuse...
#pragma once

#include <map>
#include <string>
#include <vector>

#include "bouncecal/export/native_law.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

enum class ExportTarget { kLammps, kLiggghts, kYade };
const char* ExportTargetName(ExportTarget target);  // "lammps", "liggghts", "yade"
bool ParseExportTarget(const std::string& text, ExportTarget* target);
// The simulator versions the mappings were verified against (Debian 12 packages).
const char* VerifiedSimulatorVersion(ExportTarget target);

struct Mapping {
  ExportTarget target = ExportTarget::kLammps;
  std::string law;         // the fitted bouncecal law
  std::string native_law;  // the simulator's keywords, e.g. "granular hertz ... damping tsuji"
  NativeForm form = NativeForm::kLinear;
  bool clip = false;                           // the simulator clips attractive normal forces
  double stiffness = 0.0;                      // native k, bouncecal units (N/m or N/m^1.5)
  double damping = 0.0;                        // native c (N*s/m), alpha (1) or A (s)
  std::map<std::string, double> coefficients;  // the numbers written into the deck, by name
  std::string kind;                            // "exact", "matched" or "approximated"
  bool exact = false;
  double max_e_error = 0.0;             // max |e_native(v) - e_fit(v)| over the speeds
  double max_contact_time_error = 0.0;  // max relative |t_c native - t_c fit|
  std::vector<double> speeds_m_s;       // where it was measured
  std::vector<std::string> notes;

  NativeModel Model() const { return NativeModel(form, clip, stiffness, damping); }
};

// speeds_m_s: the fitted speed range (at least one speed). Throws Error(kBadParameter) when the
// law cannot be evaluated or a native coefficient is out of the simulator's range.
Mapping MapLaw(const Scene& scene, const std::vector<double>& speeds_m_s, ExportTarget target);

// Tsuji's alpha for restitution e (F = k d^1.5 + alpha sqrt(m k) d^0.25 d'), exact, with or
// without clipping of attractive forces (bisection on bouncecal's integrator).
double TsujiAlphaForRestitution(double e, bool clip);
// LAMMPS' Tsuji polynomial alpha(e) (granular pair and wall styles, `damping tsuji`).
double LammpsTsujiPolynomial(double e);
// LIGGGHTS/Yade `hertz` damping from restitution: alpha = sqrt(5) (-ln e)/sqrt(ln^2 e + pi^2)
// (Tsuji 1992 via Antypov & Elliott 2011 eq. 17), and its inverse.
double LiggghtsHertzAlpha(double e);
double LiggghtsHertzRestitution(double alpha);

}  // namespace bouncecal

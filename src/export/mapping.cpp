// Fitted law -> native law of a simulator (mapping.hpp).
#include "bouncecal/export/mapping.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Bisection for a decreasing function f on [lo, hi]: f(x) = target.
template <typename F>
double SolveDecreasing(F f, double target, double lo, double hi) {
  for (int i = 0; i < 200 && hi - lo > 1e-15 * std::max(1.0, std::abs(hi)); ++i) {
    const double mid = 0.5 * (lo + hi);
    (f(mid) > target ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// The unit body: e of linear and Tsuji forms depends on the dimensionless damping alone.
const ContactBody kUnitBody = ContactBody::BallOnRigidWall(1.0, 1.0);

// A linear spring-dashpot (clipped or not) with restitution e and contact time t_c on mass m:
// zeta from e (unit oscillator), then omega_0 from t_c = tau(zeta) / omega_0.
void LinearForRestitutionAndTime(double e, double contact_time_s, double mass_kg, bool clip,
                                 double* k, double* c) {
  auto e_of_zeta = [clip](double zeta) {
    return NativeModel(NativeForm::kLinear, clip, 1.0, 2.0 * zeta).RestitutionAt(kUnitBody, 1.0);
  };
  const double zeta = SolveDecreasing(e_of_zeta, e, 0.0, clip ? 50.0 : 0.999);
  const double tau = NativeModel(NativeForm::kLinear, clip, 1.0, 2.0 * zeta)
                         .ContactTimeAt(kUnitBody, 1.0);  // omega_0 = 1
  const double omega0 = tau / contact_time_s;
  *k = mass_kg * omega0 * omega0;
  *c = 2.0 * zeta * mass_kg * omega0;
}

struct Fit {
  const Scene& scene;
  std::unique_ptr<ContactLaw> law;
  std::vector<double> p;
  ContactBody body;
  std::vector<double> e, tc;  // at the speeds

  Fit(const Scene& s, const std::vector<double>& speeds) : scene(s) {
    law = CreateLaw(s.law, s);
    p = law->ParameterValues();
    body = BodyFromScene(s);
    for (double v : speeds) {
      const ContactOutcome c = SimulateContact(*law, p, body, v, 0.0);
      e.push_back(c.stuck ? 0.0 : c.restitution);
      tc.push_back(c.contact_time_s);
    }
  }
  double Param(const std::string& name) const {
    return p[static_cast<size_t>(law->ParameterIndex(name))];
  }
  double EMin() const { return *std::min_element(e.begin(), e.end()); }
  double EMax() const { return *std::max_element(e.begin(), e.end()); }
};

// Fills max_e_error and max_contact_time_error by running the native model at every speed.
void Measure(const Fit& fit, Mapping* m) {
  const NativeModel model = m->Model();
  m->max_e_error = 0.0;
  m->max_contact_time_error = 0.0;
  for (size_t i = 0; i < m->speeds_m_s.size(); ++i) {
    const double v = m->speeds_m_s[i];
    const ContactOutcome c = SimulateContact(model, model.ParameterValues(), fit.body, v, 0.0);
    m->max_e_error = std::max(m->max_e_error, std::abs(c.restitution - fit.e[i]));
    if (std::isfinite(fit.tc[i]) && fit.tc[i] > 0.0) {
      m->max_contact_time_error =
          std::max(m->max_contact_time_error, std::abs(c.contact_time_s / fit.tc[i] - 1.0));
    }
  }
}

// ---- the native laws of each target, from a native model ----------------------------------

// The deck's coefficients and keyword line of a native model on a target.
void DescribeNative(const Fit& fit, Mapping* m) {
  const double R = fit.body.radius_m, mass = fit.body.mass_kg, k = m->stiffness;
  auto& co = m->coefficients;
  switch (m->target) {
    case ExportTarget::kLammps:
      if (m->form == NativeForm::kLinear) {
        co["kn_n_m"] = k;
        co["damping_n_s_m"] = m->damping;  // damping velocity: F = -eta_n0 v_n
        m->native_law = "fix wall/gran granular hooke kn eta_n0 damping velocity";
      } else if (m->form == NativeForm::kHertzViscoelastic) {
        co["kn_pa"] = k / std::sqrt(R);  // F_ne = kn a delta, a = sqrt(R delta)
        co["eta_n0_1_m_s"] = 1.5 * m->damping * k / (mass * std::sqrt(R));  // eta_n0 a m* v_n
        m->native_law = "fix wall/gran granular hertz kn eta_n0 damping viscoelastic";
      } else {
        co["kn_pa"] = k / std::sqrt(R);
        co["alpha"] = m->damping;
        // LAMMPS converts the given e to alpha with its polynomial: give the e whose
        // polynomial alpha is the exact alpha.
        const double a = m->damping;
        if (!(a <= LammpsTsujiPolynomial(0.0) && a >= 0.0)) {
          throw Error(ErrorCode::kBadParameter,
                      "lammps: Tsuji alpha = " + FormatGeneral(a, 10) +
                          " is outside LAMMPS' alpha(e) polynomial range [0, 1.2728]");
        }
        co["e_input"] = SolveDecreasing(LammpsTsujiPolynomial, a, 0.0, 1.0);
        const double e_fit = fit.e.front();
        const double e_naive =
            NativeModel(NativeForm::kHertzTsuji, false, k, LammpsTsujiPolynomial(e_fit))
                .RestitutionAt(fit.body, 1.0);
        m->notes.push_back(
            "LAMMPS' damping tsuji turns e into alpha with a polynomial that is not "
            "Tsuji's alpha(e): e = " +
            FormatGeneral(co["e_input"], 10) + " is written so that alpha = " +
            FormatGeneral(a, 10) + " (e = " + FormatGeneral(e_fit, 10) +
            " written as it is would bounce at " + FormatGeneral(e_naive, 10) + ")");
        m->native_law = "fix wall/gran granular hertz kn e damping tsuji";
      }
      break;
    case ExportTarget::kLiggghts:
      if (m->form == NativeForm::kLinear) {
        co["k_n_n_m"] = k;
        co["gamman_abs_n_s_m"] = m->damping;
        m->native_law = "model hooke/stiffness (gamman = c / m)";
      } else if (m->form == NativeForm::kHertzViscoelastic) {
        co["k_n_pa"] = k / std::sqrt(R);  // kn = k_n sqrt(R delta)
        co["gamman_1_m_s"] = 1.5 * m->damping * k / (mass * std::sqrt(R));  // sqrt(R d) m* gamma_n
        m->native_law = "model hertz/stiffness";
      } else {
        const double a = m->damping;
        if (!(a < std::sqrt(5.0))) {
          throw Error(ErrorCode::kBadParameter, "liggghts: Tsuji alpha = " + FormatGeneral(a, 10) +
                                                    " needs alpha < sqrt(5) for model hertz");
        }
        co["coefficientRestitution"] = LiggghtsHertzRestitution(a);
        co["Yeff_pa"] = 0.75 * k / std::sqrt(R);  // kn = 4/3 Yeff sqrt(R delta)
        m->native_law = "model hertz (youngsModulus, poissonsRatio, coefficientRestitution)";
      }
      break;
    case ExportTarget::kYade:
      if (m->form == NativeForm::kLinear) {
        // ViscElMat with kn, cn given: the contact takes the series combination of both
        // materials, kn = 1/(1/kn1 + 1/kn2): both materials carry 2k and 2c.
        co["kn_n_m"] = 2.0 * k;
        co["cn_n_s_m"] = 2.0 * m->damping;
        m->notes.push_back(
            "Yade combines the two materials' kn, cn in series: each carries 2k, 2c "
            "(the tc/en form would use the reduced mass m/2 against a wall)");
        m->native_law = "ViscElMat(kn, cn) + Law2_ScGeom_ViscElPhys_Basic";
      } else {
        // MindlinPhys: Kno = 4/3 E* sqrt(R') with R' = R/2 against a wall (the wall's radius
        // is taken as the sphere's: Da = Db = R); betan on the tangent stiffness 3/2 Kno
        // sqrt(d): c_n = 2 betan sqrt(m 3/2 Kno) d^1/4, i.e. alpha = sqrt(6) betan.
        co["young_eff_pa"] = 0.75 * k / std::sqrt(0.5 * R);
        co["betan"] = m->damping / std::sqrt(6.0);
        m->notes.push_back(
            "Yade's MindlinPhys takes R/2 against a wall: E* raised by sqrt(2) so "
            "that Kno = k");
        m->native_law =
            "FrictMat + Ip2_FrictMat_FrictMat_MindlinPhys(betan) + "
            "Law2_ScGeom_MindlinPhys_Mindlin";
      }
      break;
  }
}

// ---- per-law mappings ------------------------------------------------------------------

bool TargetClips(ExportTarget t) { return t == ExportTarget::kYade; }

void MapLinearDashpot(const Fit& fit, bool force_zero, Mapping* m) {
  const double k = fit.Param("k"), c = fit.Param("c");
  m->form = NativeForm::kLinear;
  m->stiffness = k;
  // LAMMPS' and LIGGGHTS' walls keep the attractive end of the force; Yade clips it.
  const bool native_clip = TargetClips(m->target);
  m->clip = native_clip;
  if (native_clip == force_zero) {
    m->damping = c;
    m->kind = "exact";
    return;
  }
  // Other end rule: the damping that gives the same (constant) e under the native rule.
  double k2 = 0.0, c2 = 0.0;
  LinearForRestitutionAndTime(fit.e[0], fit.tc[0], fit.body.mass_kg, native_clip, &k2, &c2);
  m->stiffness = k2;
  m->damping = c2;
  m->kind = "matched";
  m->notes.push_back(std::string(ExportTargetName(m->target)) + " ends a linear contact at " +
                     (native_clip ? "F = 0 (attractive force clipped)" : "overlap 0") +
                     ", the fit at " + (force_zero ? "F = 0" : "overlap 0") +
                     ": k and c re-solved for the same e = " + FormatGeneral(fit.e[0], 10) +
                     " and contact time " + FormatGeneral(fit.tc[0], 10) + " s");
}

void MapConstantLinear(const Fit& fit, const std::string& why, Mapping* m) {
  m->form = NativeForm::kLinear;
  m->clip = TargetClips(m->target);
  LinearForRestitutionAndTime(fit.e[0], fit.tc[0], fit.body.mass_kg, m->clip, &m->stiffness,
                              &m->damping);
  m->kind = "matched";
  m->notes.push_back(why +
                     ": a linear spring-dashpot with the same e = " + FormatGeneral(fit.e[0], 10) +
                     " and contact time " + FormatGeneral(fit.tc[0], 10) +
                     " s replaces it (e and t_c are speed-independent in both; peak overlap and "
                     "force history differ)");
}

void MapHertzTsuji(const Fit& fit, Mapping* m) {
  m->form = NativeForm::kHertzTsuji;
  m->stiffness = fit.Param("k");
  m->clip = TargetClips(m->target);
  m->damping = TsujiAlphaForRestitution(fit.Param("e"), m->clip);
  m->kind = m->clip ? "matched" : "exact";
  if (m->clip) {
    m->notes.push_back(
        "Yade clips the attractive end of the contact force: alpha re-solved "
        "under the F = 0 end for the same e = " +
        FormatGeneral(fit.Param("e"), 10));
  }
}

void MapHertzViscoelastic(const Fit& fit, Mapping* m) {
  if (m->target != ExportTarget::kYade) {
    m->form = NativeForm::kHertzViscoelastic;
    m->stiffness = fit.Param("k");
    m->damping = fit.Param("A");
    m->clip = false;
    m->kind = "exact";
    return;
  }
  // Yade has no d^1/2 damping: the closest constant-e Hertz law over the measured speeds.
  m->form = NativeForm::kHertzTsuji;
  m->stiffness = fit.Param("k");
  m->clip = true;
  const double e_mid = 0.5 * (fit.EMin() + fit.EMax());
  m->damping = TsujiAlphaForRestitution(e_mid, true);
  m->kind = "approximated";
  m->notes.push_back(
      "yade has no viscoelastic Hertz damping (d^1/2 d'): Hertz-Mindlin with the "
      "constant e = " +
      FormatGeneral(e_mid, 10) + " closest to the fitted e(v) = " + FormatGeneral(fit.EMin(), 10) +
      " .. " + FormatGeneral(fit.EMax(), 10) + " over the measured speeds");
}

// A registry row's export note with "{target}" replaced by the simulator's name.
std::string WithTarget(std::string note, ExportTarget target) {
  const std::size_t at = note.find("{target}");
  if (at != std::string::npos) note.replace(at, 8, ExportTargetName(target));
  return note;
}

// Any other law: a constant-e Hertz law (the target's Tsuji form) with the middle e of the
// fitted range and the fit's contact time at the geometric middle speed.
void MapClosestHertz(const Fit& fit, Mapping* m) {
  m->form = NativeForm::kHertzTsuji;
  m->clip = TargetClips(m->target);
  const double e_mid = 0.5 * (fit.EMin() + fit.EMax());
  m->damping = TsujiAlphaForRestitution(e_mid, m->clip);
  const size_t mid = m->speeds_m_s.size() / 2;
  const double v = m->speeds_m_s[mid];
  // t_c scales as (m/k)^(2/5) v^(-1/5): solve k from the unit-k contact time.
  const NativeModel unit(NativeForm::kHertzTsuji, m->clip, 1.0, m->damping);
  const double tc_unit = unit.ContactTimeAt(fit.body, v);
  m->stiffness = std::pow(tc_unit / fit.tc[mid], 2.5);
  m->kind = "approximated";
  m->notes.push_back(
      std::string(ExportTargetName(m->target)) + " has no native " + fit.law->Name() +
      ": a Hertz law with the constant e = " + FormatGeneral(e_mid, 10) + " (fitted e(v) " +
      FormatGeneral(fit.EMin(), 10) + " .. " + FormatGeneral(fit.EMax(), 10) +
      ") and the fit's contact time at " + FormatGeneral(v, 10) + " m/s");
}

}  // namespace

const char* ExportTargetName(ExportTarget target) {
  switch (target) {
    case ExportTarget::kLammps:
      return "lammps";
    case ExportTarget::kLiggghts:
      return "liggghts";
    case ExportTarget::kYade:
      return "yade";
  }
  return "?";
}

bool ParseExportTarget(const std::string& text, ExportTarget* target) {
  for (ExportTarget t : {ExportTarget::kLammps, ExportTarget::kLiggghts, ExportTarget::kYade}) {
    if (text == ExportTargetName(t)) {
      *target = t;
      return true;
    }
  }
  return false;
}

const char* VerifiedSimulatorVersion(ExportTarget target) {
  switch (target) {
    case ExportTarget::kLammps:
      return "LAMMPS 29 Sep 2021 - Update 2";
    case ExportTarget::kLiggghts:
      return "LIGGGHTS-PUBLIC 3.8.0";
    case ExportTarget::kYade:
      return "Yade 2023.02a";
  }
  return "?";
}

double LammpsTsujiPolynomial(double e) {
  // LAMMPS src/GRANULAR (pair granular, fix wall/gran granular), `damping tsuji`.
  const double c[] = {1.2728, -4.2783, 11.087, -22.348, 27.467, -18.022, 4.8218};
  double a = 0.0, x = 1.0;
  for (double ci : c) {
    a += ci * x;
    x *= e;
  }
  return a;
}

double LiggghtsHertzAlpha(double e) {
  const double l = std::log(e);
  return std::sqrt(5.0) * (-l) / std::sqrt(l * l + kPi * kPi);
}

double LiggghtsHertzRestitution(double alpha) {
  // alpha^2 (u^2 + pi^2) = 5 u^2, u = -ln e.
  const double u = alpha * kPi / std::sqrt(5.0 - alpha * alpha);
  return std::exp(-u);
}

double TsujiAlphaForRestitution(double e, bool clip) {
  if (e >= 1.0) return 0.0;
  auto e_of_alpha = [clip](double a) {
    return NativeModel(NativeForm::kHertzTsuji, clip, 1.0, a).RestitutionAt(kUnitBody, 1.0);
  };
  return SolveDecreasing(e_of_alpha, e, 0.0, 2.0);
}

Mapping MapLaw(const Scene& scene, const std::vector<double>& speeds_m_s, ExportTarget target) {
  if (speeds_m_s.empty()) {
    throw Error(ErrorCode::kBadParameter, "mapping: no impact speeds to map the law over");
  }
  const Fit fit(scene, speeds_m_s);
  Mapping m;
  m.target = target;
  m.law = scene.law.name;
  m.speeds_m_s = speeds_m_s;
  const LawInfo* row = FindLaw(scene.law.name);
  switch (row != nullptr ? row->export_mapping : ExportMapping::kClosestHertz) {
    case ExportMapping::kLinearDashpot:
      MapLinearDashpot(fit, row->end_rule == ContactEnd::kForceZero, &m);
      break;
    case ExportMapping::kConstantLinear:
      MapConstantLinear(fit, WithTarget(row->export_note, target), &m);
      break;
    case ExportMapping::kHertzTsuji:
      MapHertzTsuji(fit, &m);
      break;
    case ExportMapping::kHertzViscoelastic:
      MapHertzViscoelastic(fit, &m);
      break;
    case ExportMapping::kClosestHertz:
      MapClosestHertz(fit, &m);
      break;
  }
  m.exact = m.kind == "exact";
  DescribeNative(fit, &m);
  Measure(fit, &m);
  if (m.exact) m.max_e_error = 0.0;  // same force law: any difference is integrator noise
  return m;
}

}  // namespace bouncecal

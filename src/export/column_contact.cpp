// The column's contacts (column.hpp): the paper's Hertz-Mindlin law with Tsuji damping carried
// from the fits' mappings, every coefficient LAMMPS and Yade need for the same forces, and the
// time step.
//
// Yade's Ip2_FrictMat_FrictMat_MindlinPhys + Law2_ScGeom_MindlinPhys_Mindlin (the paper's code)
// defines the forces; the LAMMPS coefficients are chosen to give the same ones:
//   normal:     F = Kno d^1.5 + 2 betan sqrt(m* 3/2 Kno) d^1/4 v,  Kno = 4/3 E* sqrt(R')
//               LAMMPS `hertz kn e' damping tsuji`: kn = 4/3 E*, alpha = sqrt(6) betan
//   tangential: ks = Kso sqrt(d), Kso = 4 G sqrt(R') / (2 - nu), G and nu the two materials'
//               arithmetic means (Yade's rule); damping 2 betan sqrt(m* ks)
//               LAMMPS `tangential mindlin kt x mu`: F = kt a xi, a = sqrt(R* d), damping x eta_n
//               with x = sqrt(ks / (3/2 Kno sqrt(d)))
//   rolling:    Yade: moment spring krot, limit eta R_mean F_n (R_mean = (R1 + R2)/2)
//               LAMMPS `rolling sds k_roll 0 mu_roll`: torque R* k_roll xi, limit mu_roll R* F_n
// R' is R* between spheres and R/2 against a Yade wall (it takes the sphere's radius for the
// wall's); LAMMPS' walls have R* = R. Yade's wall material is stiffened so that its Kno equals
// LAMMPS' (E* raised by sqrt 2). Sources: Yade 2023.02a HertzMindlin.cpp, LAMMPS 29 Sep 2021
// pair_granular.cpp / fix_wall_gran.cpp, docs/physics.md §10.2, docs/column.md.
#include <algorithm>
#include <cmath>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/export/column.hpp"
#include "bouncecal/physics/scene.hpp"
#include "export/column_deck.hpp"
#include "fit/text.hpp"

namespace bouncecal {
namespace {

// The time step starts at the shortest contact time / 10 (the common DEM rule; seed 002's
// packing used t_c/4.5) and is halved at most 6 times until its e error is within budget.
constexpr double kStepsPerContactStart = 10.0;
constexpr int kMaxHalvings = 6;
// The rolling spring's reference load: the mean contact force at the column's base, the weight
// of the column above one bead's cross-section at the paper's solid fraction (25167 beads of
// mean volume in 100 x 200 x 180 mm: 0.58).
constexpr double kPaperSolidFraction = 0.58;

double EffectiveModulus(double e1, double nu1, double e2, double nu2) {
  return 1.0 / ((1.0 - nu1 * nu1) / e1 + (1.0 - nu2 * nu2) / e2);  // Johnson (1985) eq. 4.22
}

// Yade's Kso / sqrt(R'): 4 G / (2 - nu) with G, nu the means of the two materials'.
double YadeShearCoefficient(double e1, double nu1, double e2, double nu2) {
  const double g = 0.5 * (e1 / (2.0 * (1.0 + nu1)) + e2 / (2.0 * (1.0 + nu2)));
  return 4.0 * g / (2.0 - 0.5 * (nu1 + nu2));
}

bool Clips(ExportTarget t) { return t == ExportTarget::kYade; }

double SphereMass(double d) { return ColumnPaper::kDensity_kg_m3 * M_PI * d * d * d / 6.0; }

struct PairGeometry {
  double mass_kg, radius_m;   // reduced (a fixed partner: the bead's own mass)
  double lammps_radius_m;     // R* as LAMMPS' torque arm (R for a wall)
  double yade_mean_radius_m;  // Yade's R_mean for the rolling limit
};

ColumnContact MakeContact(const std::string& name, const ColumnFit& fit, double given_e,
                          ExportTarget target, double e_star, double yade_e_star,
                          double yade_kso_coef, double yade_radius_factor, const PairGeometry& g,
                          const ColumnPlan& plan) {
  ColumnContact c;
  c.name = name;
  c.restitution = given_e > 0.0 ? given_e : fit.restitution;
  c.e_error = given_e > 0.0 ? 0.0 : fit.e_error;
  c.alpha = TsujiAlphaForRestitution(c.restitution, Clips(target));
  c.e_input_lammps = exporter::LammpsTsujiInput(c.alpha);
  c.yade_betan = c.alpha / std::sqrt(6.0);
  c.kn_pa = 4.0 / 3.0 * e_star;
  // Yade: ks / (3/2 Kno sqrt d) with both on the same R' (the factors of R' cancel).
  c.tangential_damping_ratio = std::sqrt(yade_kso_coef / (2.0 * yade_e_star));
  c.kt_pa = yade_kso_coef * yade_radius_factor;  // LAMMPS a = sqrt(R* d); Yade sqrt(R' d)
  c.rolling_mu_lammps = plan.rolling_friction * g.yade_mean_radius_m / g.lammps_radius_m;
  c.rolling_k_lammps = plan.rolling_stiffness_nm_rad / (g.lammps_radius_m * g.lammps_radius_m);
  c.reduced_mass_kg = g.mass_kg;
  c.reduced_radius_m = g.radius_m;
  const double k = c.kn_pa * std::sqrt(g.radius_m);
  const NativeModel model(NativeForm::kHertzTsuji, Clips(target), k, c.alpha);
  c.contact_time_s = model.ContactTimeAt(ContactBody::BallOnRigidWall(g.mass_kg, g.radius_m),
                                         std::sqrt(2.0 * 9.8 * ColumnPaper::kColumnHeight_m));
  return c;
}

}  // namespace

namespace exporter {

double LammpsTsujiInput(double alpha) {
  // LammpsTsujiPolynomial falls from 1.2728 at e = 0 to 0 at e = 1: bisection.
  if (!(alpha >= 0.0 && alpha <= LammpsTsujiPolynomial(0.0))) {
    throw Error(ErrorCode::kBadParameter,
                "lammps: Tsuji alpha = " + FormatShortest(alpha) +
                    " is outside LAMMPS' alpha(e) polynomial range "
                    "[0, 1.2728] (restitution too low for damping tsuji)");
  }
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 200 && hi - lo > 1e-15; ++i) {
    const double mid = 0.5 * (lo + hi);
    (LammpsTsujiPolynomial(mid) > alpha ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

ColumnFit MakeColumnFit(const std::string& params_path, const Mapping& m, const ContactBody& body,
                        const std::vector<double>& e_fit) {
  ColumnFit f;
  f.params_path = params_path;
  f.mapping = m;
  const NativeModel native = m.Model();
  std::vector<double> e_native;
  for (double v : m.speeds_m_s) e_native.push_back(native.RestitutionAt(body, v));
  const auto [lo, hi] = std::minmax_element(e_native.begin(), e_native.end());
  // Tsuji and linear native laws have one e at every speed; a viscoelastic one does not: the
  // column (Tsuji between every pair) takes the middle of its range.
  f.restitution = 0.5 * (*lo + *hi);
  for (size_t i = 0; i < e_fit.size() && i < e_native.size(); ++i) {
    f.e_error = std::max(f.e_error, std::abs(f.restitution - e_fit[i]));
  }
  f.notes.push_back(params_path + ": " + m.law + " mapped to " + m.native_law + " [" + m.kind +
                    "], e = " + FormatGeneral(f.restitution, 4) +
                    " carried to every pair as Tsuji's alpha; "
                    "|e - e_fit| <= " +
                    FormatGeneral(f.e_error, 4) + " over " +
                    FormatGeneral(m.speeds_m_s.front(), 4) + " .. " +
                    FormatGeneral(m.speeds_m_s.back(), 4) + " m/s");
  return f;
}

}  // namespace exporter

ColumnPlan PlanColumn(const ColumnOptions& o, ExportTarget target, const ColumnFit& bead,
                      const ColumnFit& wall) {
  ColumnPlan p = exporter::ColumnGeometry(o, target);
  p.bead_fit = bead;
  p.wall_fit = wall;
  const MaterialPreset& ceramic = *FindMaterial("ceramic");
  const MaterialPreset& plastic = *FindMaterial("plastic");
  p.poisson_ratio = ceramic.poisson_ratio;
  p.wall_youngs_pa = plastic.youngs_modulus_pa;
  p.wall_poisson = plastic.poisson_ratio;
  const double eb = ceramic.youngs_modulus_pa, nb = ceramic.poisson_ratio;
  const double ew = plastic.youngs_modulus_pa, nw = plastic.poisson_ratio;
  const double e_bb = EffectiveModulus(eb, nb, eb, nb), e_bw = EffectiveModulus(eb, nb, ew, nw);
  // Yade's wall: E* raised by sqrt 2 to undo its R' = R/2 (needs sqrt2 E*_bw below the bead's own
  // E/(1 - nu^2), true for plastic walls).
  const double target_inv = 1.0 / (std::sqrt(2.0) * e_bw) - (1.0 - nb * nb) / eb;
  p.yade_wall_youngs_pa = (1.0 - nw * nw) / target_inv;

  const double r = 0.5 * p.d_mean_m, rf = 0.5 * p.floor_diameter_m;
  // Rolling stiffness (Iwashita & Oda 1998, as Wensrich & Katterfeld 2012 recommend): k_r =
  // k_t R*^2 with k_t the Mindlin tangential stiffness of a mean bead pair at the reference load.
  {
    const double r_star = 0.5 * r, k = 4.0 / 3.0 * e_bb * std::sqrt(r_star);
    const double load = ColumnPaper::kDensity_kg_m3 * kPaperSolidFraction * 9.8 *
                        ColumnPaper::kColumnHeight_m * p.d_mean_m * p.d_mean_m;
    const double overlap = std::pow(load / k, 2.0 / 3.0);
    const double kt = YadeShearCoefficient(eb, nb, eb, nb) * std::sqrt(r_star * overlap);
    p.rolling_stiffness_nm_rad = kt * r_star * r_star;
  }
  const double given = o.restitution;
  const double m_min = SphereMass(p.d_min_m), r_min = 0.5 * p.d_min_m;
  // Contact times of the smallest pairs (the time step's bound); the rolling arms at mean sizes.
  PairGeometry bb{0.5 * m_min, 0.5 * r_min, 0.5 * r, r};
  PairGeometry bf{m_min, r_min * rf / (r_min + rf), r * rf / (r + rf), 0.5 * (r + rf)};
  PairGeometry bw{m_min, r_min, r, r};
  const double kso_bb = YadeShearCoefficient(eb, nb, eb, nb);
  p.bead_bead = MakeContact("bead-bead", bead, given, target, e_bb, e_bb, kso_bb, 1.0, bb, p);
  p.bead_floor = MakeContact("bead-floor", wall, given, target, e_bb, e_bb, kso_bb, 1.0, bf, p);
  // Against a Yade wall Kno and Kso are taken on R/2: LAMMPS' kt (on a = sqrt(R d)) is Yade's
  // Kso / sqrt 2, and the damping ratio is Yade's (its stiffened wall's E*).
  p.bead_wall = MakeContact(
      "bead-wall", wall, given, target, e_bw, EffectiveModulus(eb, nb, p.yade_wall_youngs_pa, nw),
      YadeShearCoefficient(eb, nb, p.yade_wall_youngs_pa, nw), 1.0 / std::sqrt(2.0), bw, p);

  // Time step: shortest contact time / 10, halved until the leapfrog's e error for the smallest
  // bead pair at the rest speed and the largest impact speed is within budget.
  const double tc = std::min(
      {p.bead_bead.contact_time_s, p.bead_floor.contact_time_s, p.bead_wall.contact_time_s});
  const NativeModel pair(NativeForm::kHertzTsuji, Clips(target),
                         p.bead_bead.kn_pa * std::sqrt(bb.radius_m), p.bead_bead.alpha);
  const ContactBody body = ContactBody::BallOnRigidWall(bb.mass_kg, bb.radius_m);
  const std::vector<double> speeds = {p.rest_speed_m_s,
                                      std::sqrt(2.0 * 9.8 * ColumnPaper::kColumnHeight_m)};
  double dt = tc / kStepsPerContactStart;
  int halvings = 0;
  p.time_step_e_error = MaxTimeStepError(pair, body, speeds, dt, 0.0);
  while (p.time_step_e_error > o.dt_e_error && halvings < kMaxHalvings) {
    dt *= 0.5;
    ++halvings;
    p.time_step_e_error = MaxTimeStepError(pair, body, speeds, dt, 0.0);
  }
  p.time_step_s = dt;
  p.time_step_choice = "shortest contact time " + FormatGeneral(tc, 4) + " s (smallest beads at " +
                       FormatGeneral(speeds[1], 4) + " m/s, free fall from the column top) / " +
                       FormatGeneral(kStepsPerContactStart * std::pow(2.0, halvings), 4) +
                       ": leapfrog e error " + FormatGeneral(p.time_step_e_error, 4) + " (budget " +
                       FormatGeneral(o.dt_e_error, 4) + ") at " + FormatGeneral(speeds[0], 4) +
                       " and " + FormatGeneral(speeds[1], 4) + " m/s";
  p.settle_steps = static_cast<long>(std::ceil(p.settle_max_s / dt));
  p.collapse_steps = static_cast<long>(std::ceil(p.max_collapse_s / dt));
  p.dump_every = std::max<long>(1, std::lround(p.dump_interval_s / dt));
  p.dump_interval_s = static_cast<double>(p.dump_every) * dt;
  return p;
}

}  // namespace bouncecal

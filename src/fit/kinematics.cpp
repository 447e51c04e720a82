// Impact times -> per-bounce speeds, restitution and energy loss (kinematics.hpp).
//
// Notation: onsets t_0 < t_1 < ... (sigma s_k each, independent), interval I_k = t_{k+1} - t_k,
// contact duration tau_k of impact k (0 unless the scene's contact_duration effect is on),
// flight time T_k = I_k - tau_k (the ball leaves the plate tau_k after the onset and touches it
// again at the next onset). With the scene's flight model F (flight.hpp, docs/physics.md §2):
//   v_out,k   = F^-1(T_k)                       (exact inversion of the flight time)
//   v_in,k+1  = A(v_out,k)                      (arrival speed after that flight)
//   e_k = v_out,k / v_in,k,   eta_k = 1 - e_k^2 (seed 002 eqs. 11-12)
// Without drag this is exactly e_k = I_k / I_{k-1} (seed 002 eq. 11). v_in,0 comes from the drop
// (fall from height h, or the given impact speed) when the scene has it.
//
// Uncertainty (first order, onsets independent): with a_k = dv_out,k/dT_k = 1/F'(v_out,k) and
// b_k = dA/dv0 at v_out,k,
//   de_k/dt_{k+1} =  a_k / v_in,k
//   de_k/dt_k     = -a_k / v_in,k - e_k b_{k-1} a_{k-1} / v_in,k
//   de_k/dt_{k-1} =  e_k b_{k-1} a_{k-1} / v_in,k
// so e_k and e_{k+1} share t_k and t_{k+1} and are correlated (reported per bounce), and the
// sigma of the mean eta of three bounces is computed from the gradient of the mean with respect
// to every onset, not from the individual sigmas. The weak dependence of the Hertz contact time
// on the impact speed (tau ~ v^-1/5) is left out of the Jacobian.
#include "bouncecal/fit/kinematics.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/fit/bounce_screen.hpp"
#include "bouncecal/physics/flight.hpp"
#include "fit/text.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

bool AnalysisOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error != nullptr) *error = m;
    return false;
  };
  if (!std::isfinite(contact_time_s) || contact_time_s < 0.0) {
    return fail("contact_time_s: must be finite and >= 0 (0 = Hertz estimate) (got " +
                Printf("%g", contact_time_s) + ")");
  }
  if (!(irregular_alpha > 0.0 && irregular_alpha < 1.0)) {
    return fail("irregular_alpha: must be in (0, 1) (got " + Printf("%g", irregular_alpha) + ")");
  }
  if (!(drop_z_max > 0.0) || !std::isfinite(drop_z_max)) {
    return fail("drop_z_max: must be finite and > 0 (got " + Printf("%g", drop_z_max) + ")");
  }
  if (!(drag_effect_sigmas > 0.0) || !std::isfinite(drag_effect_sigmas)) {
    return fail("drag_effect_sigmas: must be finite and > 0 (got " +
                Printf("%g", drag_effect_sigmas) + ")");
  }
  return true;
}

double HertzContactTime(const Scene& scene, double impact_speed_m_s) {
  // Effective modulus (the one rule: EffectiveModulusPa, scene.hpp) and mass (Johnson, Contact
  // Mechanics, 1985, §4.2 and §11.4).
  std::string why;
  const std::optional<double> e_star_pa = EffectiveModulusPa(scene, &why);
  if (!e_star_pa) {
    throw Error(ErrorCode::kBadScene, (scene.source.empty() ? "" : scene.source + ": ") + why +
                                          " (needed for the Hertz contact duration)");
  }
  const double e_star = *e_star_pa;
  const double m = scene.ball.Mass();
  double m_star = m;
  if (scene.effects.surface_compliance && scene.surface.mass_kg > 0.0) {
    m_star = m * scene.surface.mass_kg / (m + scene.surface.mass_kg);
  }
  const double r_star = scene.ball.Radius();
  const double v = std::max(impact_speed_m_s, 1e-12);
  // tau = 2.94 delta_max / v = 2.87 (m*^2 / (R* E*^2 v))^(1/5)  (docs/physics.md §2; Johnson,
  // Contact Mechanics, 1985, §11.4).
  return 2.87 * std::pow(m_star * m_star / (r_star * e_star * e_star * v), 0.2);
}

namespace {

// Per-onset arrays of the flight stage: speeds, their derivatives and contact durations.
struct Flights {
  std::vector<double> t, s, v_in, v_in_sigma, v_out, v_out_sigma, a, b, tau;
  double dv_in0_dh = 0.0;  // first impact from a height: d v_in,0 / d h
};

void CheckSequence(const Sequence& sequence, const Scene& scene, const AnalysisOptions& options) {
  std::string error;
  if (!scene.IsValid(&error)) throw Error(ErrorCode::kBadScene, error);
  if (!options.IsValid(&error)) throw Error(ErrorCode::kBadParameter, "analysis: " + error);
  const std::vector<Impact>& imp = sequence.impacts;
  const size_t n = imp.size();
  if (n < 2) {
    throw Error(ErrorCode::kNoBounces, "the sequence has " + std::to_string(n) +
                                           " impact(s); at least 2 are needed for kinematics");
  }
  for (size_t k = 0; k < n; ++k) {
    if (!std::isfinite(imp[k].time_s) || (k > 0 && !(imp[k].time_s > imp[k - 1].time_s))) {
      throw Error(ErrorCode::kBadParameter, "impact " + std::to_string(k) +
                                                ": times must be finite and increasing (got " +
                                                Printf("%.9g", imp[k].time_s) + ")");
    }
  }
}

// Stage 1: every interval -> rebound speed, next arrival speed, their sigmas and derivatives.
Flights FlightStage(const Sequence& sequence, const Scene& scene, const AnalysisOptions& options,
                    const FlightModel& flight, Analysis* out) {
  const std::vector<Impact>& imp = sequence.impacts;
  const size_t n = imp.size();
  const std::set<int> missed(sequence.missed_after.begin(), sequence.missed_after.end());
  Flights f;
  f.t.resize(n), f.s.resize(n), f.v_in.assign(n, kNaN), f.v_in_sigma.assign(n, kNaN);
  f.v_out.assign(n, kNaN), f.v_out_sigma.assign(n, kNaN), f.a.assign(n, kNaN);
  f.b.assign(n, kNaN), f.tau.assign(n, 0.0);
  for (size_t k = 0; k < n; ++k) {
    f.t[k] = imp[k].time_s;
    f.s[k] = std::isfinite(imp[k].sigma_s) && imp[k].sigma_s > 0.0 ? imp[k].sigma_s : 0.0;
  }
  if (!options.use_drop) {
    // First arrival speed unknown.
  } else if (scene.drop.height_m) {
    const double h = *scene.drop.height_m;
    f.v_in[0] = flight.FallArrivalSpeed(h);
    const double dh = 1e-6 * h;
    f.dv_in0_dh = (flight.FallArrivalSpeed(h + dh) - flight.FallArrivalSpeed(h - dh)) / (2 * dh);
    out->height_sigma_m = scene.drop.height_sigma_m.value_or(0.0);
    f.v_in_sigma[0] = std::abs(f.dv_in0_dh) * out->height_sigma_m;
  } else if (scene.drop.impact_speed_m_s) {
    f.v_in[0] = *scene.drop.impact_speed_m_s;
    f.v_in_sigma[0] = 0.0;
  }

  const bool contact = scene.effects.contact_duration;
  auto contact_time = [&](double v) {
    if (!contact) return 0.0;
    if (options.contact_time_of_speed) return options.contact_time_of_speed(v);
    if (options.contact_time_s > 0.0) return options.contact_time_s;
    return HertzContactTime(scene, v);
  };
  for (size_t k = 0; k + 1 < n; ++k) {
    const double interval = f.t[k + 1] - f.t[k];
    if (contact) {
      if (std::isfinite(f.v_in[k])) {
        f.tau[k] = contact_time(f.v_in[k]);
      } else {
        // Unknown arrival speed (first heard impact): tau depends on v only as v^-1/5, so a
        // few fixed-point steps with the rebound speed as the proxy converge.
        double v = 0.5 * flight.gravity_m_s2() * interval;
        for (int it = 0; it < 4; ++it) {
          f.tau[k] = contact_time(v);
          if (!(interval - f.tau[k] > 0.0)) break;
          v = flight.LaunchSpeedForFlightTime(interval - f.tau[k]);
        }
      }
    }
    if (missed.count(static_cast<int>(k))) {
      out->warnings.push_back(
          {"missed_impact",
           "interval " + std::to_string(k) + "-" + std::to_string(k + 1) +
               ": an impact seems missing; speeds and e around it are not given",
           static_cast<int>(k),
           "listen to the impacts kept (detect --click-track FILE.wav); a bounce heard there but "
           "not kept can be added in an --impacts file (detect --json)"});
      continue;
    }
    const double flight_time = interval - f.tau[k];
    if (!(flight_time > 0.0)) {
      out->warnings.push_back({"interval_too_short",
                               "interval " + std::to_string(k) + "-" + std::to_string(k + 1) +
                                   Printf(": %.3g s is not longer than the contact duration %.3g s",
                                          interval, f.tau[k]),
                               static_cast<int>(k),
                               "check the ball's size and material (--diameter, --material): "
                               "they set the contact duration"});
      continue;
    }
    f.v_out[k] = flight.LaunchSpeedForFlightTime(flight_time);
    f.a[k] = 1.0 / flight.FlightTimeDerivative(f.v_out[k]);
    f.b[k] = flight.ArrivalSpeedDerivative(f.v_out[k]);
    f.v_out_sigma[k] = f.a[k] * std::hypot(f.s[k], f.s[k + 1]);
    f.v_in[k + 1] = flight.ArrivalSpeed(f.v_out[k]);
    f.v_in_sigma[k + 1] = f.b[k] * f.a[k] * std::hypot(f.s[k], f.s[k + 1]);
  }
  if (contact && std::isfinite(f.v_in[n - 1])) f.tau[n - 1] = contact_time(f.v_in[n - 1]);
  return f;
}

// Stage 2: per bounce e = v_out / v_in with its derivatives and sigma; correlations.
void BounceStage(const Flights& f, Analysis* out) {
  const size_t n = f.t.size();
  out->bounces.resize(n);
  for (size_t k = 0; k < n; ++k) {
    Bounce& bo = out->bounces[k];
    bo.index = static_cast<int>(k);
    bo.time_s = f.t[k];
    bo.time_sigma_s = f.s[k];
    bo.interval_s = k + 1 < n ? f.t[k + 1] - f.t[k] : kNaN;
    bo.v_in_m_s = f.v_in[k];
    bo.v_in_sigma_m_s = f.v_in_sigma[k];
    bo.v_out_m_s = f.v_out[k];
    bo.v_out_sigma_m_s = f.v_out_sigma[k];
    bo.contact_s = f.tau[k];
    bo.e = bo.e_sigma = bo.e_total_sigma = bo.eta = bo.eta_sigma = kNaN;
    bo.de_dt_prev = bo.de_dt_this = bo.de_dt_next = kNaN;
    bo.e_next_correlation = kNaN;
    if (!(std::isfinite(f.v_out[k]) && std::isfinite(f.v_in[k]) && f.v_in[k] > 0.0)) continue;
    bo.e = f.v_out[k] / f.v_in[k];
    bo.de_dt_next = f.a[k] / f.v_in[k];
    double height_var = 0.0;
    if (k == 0) {
      // v_in,0 from the scene: no dependence on any onset; on the drop height if one is given.
      bo.de_dt_prev = 0.0;
      bo.de_dt_this = -f.a[k] / f.v_in[k];
      bo.dv_in_dh = f.dv_in0_dh;
      bo.de_dh = -bo.e / f.v_in[0] * f.dv_in0_dh;
      height_var = std::pow(bo.de_dh * out->height_sigma_m, 2);
    } else {
      const double dv = f.b[k - 1] * f.a[k - 1];  // dv_in,k / dt_k
      bo.dv_in_dt_this = dv;
      bo.dv_in_dt_prev = -dv;
      const double d_in = dv / f.v_in[k];  // (dv_in,k/dt_k) / v_in,k
      bo.de_dt_prev = bo.e * d_in;
      bo.de_dt_this = -f.a[k] / f.v_in[k] - bo.e * d_in;
    }
    const double sp = k > 0 ? f.s[k - 1] : 0.0;
    bo.e_sigma = std::sqrt(bo.de_dt_prev * bo.de_dt_prev * sp * sp +
                           bo.de_dt_this * bo.de_dt_this * f.s[k] * f.s[k] +
                           bo.de_dt_next * bo.de_dt_next * f.s[k + 1] * f.s[k + 1] + height_var);
    bo.e_total_sigma = bo.e_sigma;
    bo.eta = 1.0 - bo.e * bo.e;
    bo.eta_sigma = 2.0 * std::abs(bo.e) * bo.e_sigma;
    if (bo.e > 1.0) {
      out->warnings.push_back(
          {"e_above_one",
           "impact " + std::to_string(k) + Printf(": e = %.5f > 1 (+- %.2g): ", bo.e, bo.e_sigma) +
               (k == 0 ? "the drop height/impact speed is too low for the first interval, or the "
                         "first detected impact is not the drop's first"
                       : "timing noise, a wrong scene (drag) or a mis-tracked impact"),
           static_cast<int>(k),
           k == 0 ? "check the drop height (--height, of the ball's bottom) and that the "
                    "recording starts before the drop's first impact"
                  : "check the drag (--drag quadratic) and listen to the impacts (detect "
                    "--click-track FILE.wav)"});
    }
  }
  // Correlation of successive e's: shared onsets t_k (e_k's "this", e_{k+1}'s "prev") and
  // t_{k+1} (e_k's "next", e_{k+1}'s "this").
  for (size_t k = 0; k + 1 < n; ++k) {
    Bounce& p = out->bounces[k];
    const Bounce& q = out->bounces[k + 1];
    if (!std::isfinite(p.e) || !std::isfinite(q.e)) continue;
    const double cov = p.de_dt_this * q.de_dt_prev * f.s[k] * f.s[k] +
                       p.de_dt_next * q.de_dt_this * f.s[k + 1] * f.s[k + 1];
    const double denom = p.e_sigma * q.e_sigma;
    if (denom > 0.0) p.e_next_correlation = cov / denom;
  }
  if (std::isfinite(out->bounces[0].e)) {
    out->first_e = out->bounces[0].e;
    out->first_e_sigma = out->bounces[0].e_sigma;
  }
}

// Stage 4: mean eta of the first three bounces with a known e (seed 002 reports 0.58 over 5
// drops). Its sigma uses the gradient of the mean with respect to every onset (e's are
// correlated) and the ball's scatter sigma_s (independent per bounce).
void MeanEtaStage(const Flights& f, Analysis* out) {
  std::map<size_t, double> grad;  // onset index -> d mean_eta / d t
  double sum = 0.0, height_grad = 0.0, scatter_var = 0.0;
  const double s2 = out->scatter_e ? *out->scatter_e * *out->scatter_e : 0.0;
  for (size_t k = 0; k < out->bounces.size() && out->mean_eta_indices.size() < 3; ++k) {
    const Bounce& bo = out->bounces[k];
    if (!std::isfinite(bo.e)) continue;
    out->mean_eta_indices.push_back(static_cast<int>(k));
    sum += bo.eta;
    const double deta_de = -2.0 * bo.e / 3.0;
    if (k > 0) grad[k - 1] += deta_de * bo.de_dt_prev;
    grad[k] += deta_de * bo.de_dt_this;
    grad[k + 1] += deta_de * bo.de_dt_next;
    height_grad += deta_de * bo.de_dh;
    scatter_var += deta_de * deta_de * s2;
  }
  if (out->mean_eta_indices.size() == 3) {
    out->mean_eta_first3 = sum / 3.0;
    double var = std::pow(height_grad * out->height_sigma_m, 2) + scatter_var;
    for (const auto& [j, g] : grad) var += g * g * f.s[j] * f.s[j];
    out->mean_eta_first3_sigma = std::sqrt(var);
  } else {
    out->warnings.push_back({"no_mean_eta",
                             "fewer than three bounces with a known e: no mean eta of the first "
                             "three",
                             -1, "record more bounces (a higher drop, a quieter room)"});
  }
}

}  // namespace

Analysis AnalyzeBounces(const Sequence& sequence, const Scene& scene,
                        const AnalysisOptions& options) {
  CheckSequence(sequence, scene, options);
  const FlightModel flight = FlightModel::FromScene(scene);
  Analysis out;
  out.effective_gravity_m_s2 = flight.gravity_m_s2();
  out.terminal_speed_m_s = flight.terminal_speed_m_s();
  const Flights f = FlightStage(sequence, scene, options, flight, &out);
  BounceStage(f, &out);
  if (options.screen) ScreenBounces(scene, options, &out);  // stage 3: bounce_screen.hpp
  if (options.check_drag && scene.effects.drag == DragModel::kNone) {
    CheckDrag(sequence, scene, options, &out);
  }
  MeanEtaStage(f, &out);
  return out;
}

}  // namespace bouncecal

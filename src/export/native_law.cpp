// The simulators' native normal laws as bouncecal contact laws (native_law.hpp).
#include "bouncecal/export/native_law.hpp"

#include <algorithm>
#include <cmath>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {

const char* NativeFormName(NativeForm form) {
  switch (form) {
    case NativeForm::kLinear:
      return "linear";
    case NativeForm::kHertzTsuji:
      return "hertz_tsuji";
    case NativeForm::kHertzViscoelastic:
      return "hertz_viscoelastic";
  }
  return "?";
}

NativeModel::NativeModel(NativeForm form, bool clip, double stiffness, double damping)
    : form_(form), clip_(clip), values_{stiffness, damping} {
  const bool hertz = form != NativeForm::kLinear;
  const char* damping_unit =
      form == NativeForm::kLinear ? "N*s/m" : (form == NativeForm::kHertzTsuji ? "1" : "s");
  specs_ = {{"k", hertz ? "N/m^1.5" : "N/m", "stiffness", 0.0, 1e30, stiffness, false},
            {"damping", damping_unit, "damping coefficient", 0.0, 1e30, damping, true}};
}

std::string NativeModel::Name() const {
  return std::string("native-") + NativeFormName(form_) + (clip_ ? "-clipped" : "");
}

std::string NativeModel::Formula() const {
  std::string f;
  switch (form_) {
    case NativeForm::kLinear:
      f = "F = k d + c d'";
      break;
    case NativeForm::kHertzTsuji:
      f = "F = k d^1.5 + alpha sqrt(m* k) d^0.25 d'";
      break;
    case NativeForm::kHertzViscoelastic:
      f = "F = k (d^1.5 + 1.5 A d^0.5 d')";
      break;
  }
  return clip_ ? "max(0, " + f.substr(4) + ")" : f;
}

std::string NativeModel::Source() const {
  return "the target simulator's normal force written in bouncecal units (export/native_law)";
}

ContactEnd NativeModel::EndRule() const {
  // Clipping the attractive force to 0 frees the ball where F first reaches 0: the same motion
  // as ending the contact there (after it the clipped force stays 0 while d shrinks).
  return clip_ ? ContactEnd::kForceZero : ContactEnd::kOverlapZero;
}

double NativeModel::Force(std::span<const double> p, const ContactBody& body, double d,
                          double d_dot, const double*) const {
  if (d <= 0.0) return 0.0;
  const double k = p[0], damping = p[1];
  switch (form_) {
    case NativeForm::kLinear:
      return k * d + damping * d_dot;
    case NativeForm::kHertzTsuji:
      return k * d * std::sqrt(d) +
             damping * std::sqrt(body.mass_kg * k) * std::sqrt(std::sqrt(d)) * d_dot;
    case NativeForm::kHertzViscoelastic:
      return k * (d * std::sqrt(d) + 1.5 * damping * std::sqrt(d) * d_dot);
  }
  return 0.0;
}

double NativeModel::ElasticEnergy(std::span<const double> p, const ContactBody&, double d,
                                  const double*) const {
  if (d <= 0.0) return 0.0;
  return form_ == NativeForm::kLinear ? 0.5 * p[0] * d * d : 0.4 * p[0] * d * d * std::sqrt(d);
}

double NativeModel::RestitutionAt(const ContactBody& body, double v_in_m_s) const {
  const ContactOutcome c = SimulateContact(*this, values_, body, v_in_m_s, 0.0);
  return c.stuck ? 0.0 : c.restitution;
}

double NativeModel::ContactTimeAt(const ContactBody& body, double v_in_m_s) const {
  return SimulateContact(*this, values_, body, v_in_m_s, 0.0).contact_time_s;
}

double FixedStepRestitution(const NativeModel& model, const ContactBody& body, double v_in_m_s,
                            double dt_s, double g_m_s2, double phase) {
  // x: height of the ball's lowest point above the wall (overlap d = -x); v: velocity, up > 0.
  // Leapfrog as in the simulators: a_n = F(x_n, v_(n-1/2)) / m - g; v_(n+1/2) = v_(n-1/2) +
  // a_n dt; x_(n+1) = x_n + v_(n+1/2) dt.
  const std::vector<double> p = model.ParameterValues();
  double x = phase * v_in_m_s * dt_s;
  double v_half = -v_in_m_s;  // v_(-1/2)
  double v_in_level = v_in_m_s;
  bool touched = false;
  const long max_steps = 100000000;
  for (long n = 0; n < max_steps; ++n) {
    double f = 0.0;
    if (x < 0.0) {
      f = model.Force(p, body, -x, -v_half, nullptr);
      if (model.clip()) f = std::max(f, 0.0);
    }
    const double v_next = v_half + (f / body.mass_kg - g_m_s2) * dt_s;
    const double v_sync = 0.5 * (v_half + v_next);  // the velocity at x_n (flight: exact)
    if (!touched && x >= 0.0) {
      v_in_level = std::sqrt(v_sync * v_sync + 2.0 * g_m_s2 * x);
    }
    if (x < 0.0) touched = true;
    if (touched && x >= 0.0 && v_sync > 0.0) {
      return std::sqrt(v_sync * v_sync + 2.0 * g_m_s2 * x) / v_in_level;
    }
    if (touched && v_sync <= 0.0 && x >= 0.0) return 0.0;  // never rose back to the level
    v_half = v_next;
    x += v_half * dt_s;
  }
  throw Error(ErrorCode::kBadParameter,
              "time-step check: the contact did not end within 1e8 steps of " +
                  std::to_string(dt_s) + " s");
}

double MaxTimeStepError(const NativeModel& model, const ContactBody& body,
                        const std::vector<double>& speeds_m_s, double dt_s, double g_m_s2) {
  const int kPhases = 16;
  const std::vector<double> p = model.ParameterValues();
  double worst = 0.0;
  for (double v : speeds_m_s) {
    const ContactOutcome exact = SimulateContact(model, p, body, v, g_m_s2);
    for (int i = 0; i < kPhases; ++i) {
      const double e = FixedStepRestitution(model, body, v, dt_s, g_m_s2, (i + 0.5) / kPhases);
      worst = std::max(worst, std::abs(e - exact.restitution));
    }
  }
  return worst;
}

}  // namespace bouncecal

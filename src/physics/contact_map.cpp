// The contact map: Chebyshev panels of a contact's outcome in ln v_in (physics/contact_map.hpp).
#include "physics/contact_map.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

namespace bouncecal {
namespace {

// The outcomes a panel interpolates, each scaled to vary smoothly and slowly: the restitution,
// times, lengths and the force as they are, the energies as fractions of the impact's kinetic
// energy.
enum Field {
  kRestitution,
  kContactTime,
  kSeparationDepth,
  kPeakOverlap,
  kPeakForce,
  kWork,
  kElasticEnd,
  kPlateEnd,
  kInternalEnd,
  kBallEnergyEnd,
  kTimeScale,
  kFieldCount
};

std::array<double, kFieldCount> FieldsOf(const ContactRun& r, double v, double mass_kg) {
  const double e_kin = 0.5 * mass_kg * v * v;
  std::array<double, kFieldCount> f{};
  f[kRestitution] = r.v_out_m_s / v;
  f[kContactTime] = r.contact_s;
  f[kSeparationDepth] = r.separation_depth_m;
  f[kPeakOverlap] = r.peak_overlap_m;
  f[kPeakForce] = r.peak_force_n;
  f[kWork] = r.work_j / e_kin;
  f[kElasticEnd] = r.elastic_end_j / e_kin;
  f[kPlateEnd] = r.plate_end_j / e_kin;
  f[kInternalEnd] = r.internal_end_j / e_kin;
  f[kBallEnergyEnd] = r.ball_energy_end_j / e_kin;
  f[kTimeScale] = r.contact_time_scale_s;
  return f;
}

// How far a panel may be from a tightly integrated contact, in units of the simulation's
// relative tolerance: the restitution and the energies (as fractions of the impact's) within 0.1
// of it (the integrator's own error in e is ~0.03 of it at 1e-9 in fast contacts, bench_simulate,
// and up to ~40 times it in the slowest, gravity-dominated ones before rest), the
// contact time within 1 of its size, the separation depth within 1 of the peak overlap (it is
// 0, or a few nm for laws whose force vanishes above the surface, while its noise scales with
// the overlap), the peaks and the time scale (located on step ends and the overlap maximum,
// less accurate) within 3 of their size.
double CheckTolerance(int field, double rtol, double scale, double overlap_scale) {
  switch (field) {
    case kRestitution:
    case kWork:
    case kElasticEnd:
    case kPlateEnd:
    case kInternalEnd:
    case kBallEnergyEnd:
      return 0.1 * rtol;
    case kContactTime:
      return rtol * scale;
    case kSeparationDepth:
      return rtol * overlap_scale;
    default:
      return 3.0 * rtol * scale;
  }
}

// The Chebyshev points of the first kind on [-1, 1].
double Node(int j) { return std::cos(std::numbers::pi * (j + 0.5) / ContactMap::kNodes); }

// sum' c_k T_k(x) (the first term halved), by Clenshaw's recurrence.
double Clenshaw(const std::array<double, ContactMap::kNodes>& c, double x) {
  double b1 = 0.0, b2 = 0.0;
  for (int k = ContactMap::kNodes - 1; k >= 1; --k) {
    const double b0 = 2.0 * x * b1 - b2 + c[static_cast<std::size_t>(k)];
    b2 = b1;
    b1 = b0;
  }
  return x * b1 - b2 + 0.5 * c[0];
}

}  // namespace

ContactMap::ContactMap(Integrate integrate, const ContactRunOptions& run_options, double mass_kg,
                       double rest_speed_m_s, double stuck_restitution)
    : integrate_(std::move(integrate)),
      tight_(run_options),
      mass_kg_(mass_kg),
      rest_speed_m_s_(rest_speed_m_s),
      stuck_restitution_(stuck_restitution),
      rel_tolerance_(run_options.rel_tolerance) {
  tight_.rel_tolerance = run_options.rel_tolerance / kTighten;
  tight_.abs_tolerance = run_options.abs_tolerance / kTighten;
}

const ContactMap::Panel* ContactMap::Covering(double s) const {
  for (auto it = panels_list_.rbegin(); it != panels_list_.rend(); ++it)
    if (s >= it->s_lo && s <= it->s_hi) return &*it;
  return nullptr;
}

ContactRun ContactMap::Tight(double v) {
  ContactRunOptions o = tight_;
  o.stuck_speed_m_s = std::max(rest_speed_m_s_, stuck_restitution_ * v);
  ContactRun r = integrate_(v, o);
  steps_ += r.steps;
  return r;
}

void ContactMap::Build(double v_hi) {
  Panel p;
  p.s_hi = std::log(v_hi);
  p.s_lo = std::log(std::max(0.5 * v_hi, 1.05 * rest_speed_m_s_));
  if (!(p.s_hi - p.s_lo > std::log(1.25))) return;  // too close to rest to pay
  const double mid = 0.5 * (p.s_hi + p.s_lo), half = 0.5 * (p.s_hi - p.s_lo);
  std::array<std::array<double, kNodes>, kFieldCount> values{};
  bool separated = true;
  for (int j = 0; j < kNodes && separated; ++j) {
    const double v = std::exp(mid + half * Node(j));
    const ContactRun r = Tight(v);
    separated = r.end == ContactRun::End::kSeparated;
    const std::array<double, kFieldCount> f = FieldsOf(r, v, mass_kg_);
    for (int i = 0; i < kFieldCount; ++i) values[i][j] = f[i];
  }
  if (separated) {
    for (int i = 0; i < kFieldCount; ++i)
      for (int k = 0; k < kNodes; ++k) {
        double sum = 0.0;
        for (int j = 0; j < kNodes; ++j)
          sum += values[i][j] * std::cos(std::numbers::pi * k * (j + 0.5) / kNodes);
        p.coef[i][k] = 2.0 * sum / kNodes;
      }
    // Both ends (where a Chebyshev interpolant errs most) and a point between nodes.
    p.accepted = true;
    for (double x : {1.0, -1.0, 0.03}) {
      const double v = std::exp(mid + half * x);
      const ContactRun r = Tight(v);
      if (r.end != ContactRun::End::kSeparated) {
        p.accepted = false;
        break;
      }
      const std::array<double, kFieldCount> f = FieldsOf(r, v, mass_kg_);
      auto largest = [&](int i) {
        double a = 0.0;
        for (double y : values[i]) a = std::max(a, std::abs(y));
        return a;
      };
      const double overlap_scale = largest(kPeakOverlap);
      for (int i = 0; i < kFieldCount && p.accepted; ++i) {
        const double diff = std::abs(Clenshaw(p.coef[i], x) - f[i]);
        const double tol = CheckTolerance(i, rel_tolerance_, largest(i), overlap_scale);
        p.accepted = diff <= tol;
      }
      if (!p.accepted) break;
    }
  }
  if (p.accepted)
    ++panels_;
  else
    ++refused_;
  panels_list_.push_back(p);
}

ContactRun ContactMap::Evaluate(const Panel& p, double v) const {
  const double x =
      std::clamp((std::log(v) - 0.5 * (p.s_hi + p.s_lo)) / (0.5 * (p.s_hi - p.s_lo)), -1.0, 1.0);
  std::array<double, kFieldCount> f{};
  for (int i = 0; i < kFieldCount; ++i) f[i] = Clenshaw(p.coef[i], x);
  const double e_kin = 0.5 * mass_kg_ * v * v;
  ContactRun r;
  r.end = ContactRun::End::kSeparated;
  r.v_out_m_s = f[kRestitution] * v;
  r.contact_s = f[kContactTime];
  r.separation_depth_m = f[kSeparationDepth];
  r.peak_overlap_m = f[kPeakOverlap];
  r.peak_force_n = f[kPeakForce];
  r.work_j = f[kWork] * e_kin;
  r.elastic_end_j = f[kElasticEnd] * e_kin;
  r.plate_end_j = f[kPlateEnd] * e_kin;
  r.internal_end_j = f[kInternalEnd] * e_kin;
  r.ball_energy_end_j = f[kBallEnergyEnd] * e_kin;
  r.contact_time_scale_s = f[kTimeScale];
  return r;
}

bool ContactMap::MayServe(double v_in_m_s, double expected_contacts) const {
  if (!(rel_tolerance_ >= kMinRelTolerance) || !(v_in_m_s > 0.0) || !std::isfinite(v_in_m_s))
    return false;
  const Panel* p = Covering(std::log(v_in_m_s));
  return p != nullptr ? p->accepted : expected_contacts >= kBreakEvenContacts;
}

std::optional<ContactRun> ContactMap::Find(double v_in_m_s, double stuck_speed_m_s,
                                           double expected_contacts) {
  if (!(rel_tolerance_ >= kMinRelTolerance) || !(v_in_m_s > 0.0) || !std::isfinite(v_in_m_s))
    return std::nullopt;
  const double s = std::log(v_in_m_s);
  const Panel* p = Covering(s);
  if (p == nullptr) {
    if (!(expected_contacts >= kBreakEvenContacts)) return std::nullopt;
    Build(v_in_m_s);
    p = Covering(s);
  }
  if (p == nullptr || !p->accepted) return std::nullopt;
  ContactRun r = Evaluate(*p, v_in_m_s);
  // Near the stuck speed the contact's end is decided by the integrator, not interpolated.
  if (!(r.v_out_m_s > 1.001 * stuck_speed_m_s)) return std::nullopt;
  return r;
}

}  // namespace bouncecal

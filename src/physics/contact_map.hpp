// physics/contact_map.hpp — the contact's outcome tabulated against the impact speed, for the
// long tails of bounce sequences (SimulatorOptions::contact_map; internal to the library).
//
// Between two impacts nothing of the contact is remembered: the law's state, the plate and the
// ball start afresh, so a contact's outcome (rebound speed, duration, depths, peak force,
// energies) is a smooth function of the impact speed alone. A law whose restitution tends to
// 1 at low speed (the Hunt-Crossley family) bounces thousands of times on its way to rest, and
// the simulator integrated every one of those nearly identical contacts: 10 000 contacts, 278 000
// DOP853 steps for `simulate --law hunt-crossley-ln`.
//
// The map covers the impact speeds in panels [v/2, v] (v the arrival speed where the panel is
// needed). A panel is a Chebyshev interpolant in ln v of degree kNodes - 1 of each outcome,
// from kNodes contacts integrated at a tolerance kTighten times tighter than the simulation's.
// It is accepted only when three more contacts integrated at the same tight tolerance (both ends
// of the panel and a point inside) agree with it within a fraction of the simulation's own
// tolerance (CheckTolerance); otherwise the panel's speeds are integrated one by one, as
// without the map. A panel is built only where it pays: when the sequence's latest ratio of
// successive impact speeds predicts at least kBreakEvenContacts contacts in it (and the limits
// allow that many), i.e. restitution above ~0.995.
#pragma once

#include <array>
#include <functional>
#include <optional>
#include <vector>

#include "bouncecal/physics/contact_integrator.hpp"

namespace bouncecal {

class ContactMap {
 public:
  static constexpr int kNodes = 16;
  static constexpr int kChecks = 3;
  static constexpr double kTighten = 100.0;
  // A panel costs kNodes + kChecks contacts at the tight tolerance (~1.8 times the steps of
  // one at the simulation's): built when it will serve at least four times that.
  static constexpr double kBreakEvenContacts = 4.0 * 1.8 * (kNodes + kChecks);
  // Below this simulation tolerance the map is not built (its nodes would need a tolerance
  // under the integrator's floor, 1e-15).
  static constexpr double kMinRelTolerance = 1e-11;

  // integrate(v_in, options) runs one contact as the simulator does (options carries the
  // stuck speed); run_options are the simulation's.
  using Integrate = std::function<ContactRun(double v_in_m_s, const ContactRunOptions& options)>;
  ContactMap(Integrate integrate, const ContactRunOptions& run_options, double mass_kg,
             double rest_speed_m_s, double stuck_restitution);

  // The outcome of a contact at v_in_m_s from the map (steps = 0) when a panel covers it and
  // the interpolated rebound is clearly faster than stuck_speed_m_s; builds a panel first when
  // none covers the speed and `expected_contacts` (the contacts the sequence would still make
  // down to v_in / 2) makes it pay. nullopt: integrate this contact as usual.
  std::optional<ContactRun> Find(double v_in_m_s, double stuck_speed_m_s, double expected_contacts);

  // Whether Find could serve a contact at v_in_m_s (an accepted panel covers it, or none does
  // and expected_contacts would pay for one): a cheap test before the caller's own checks.
  bool MayServe(double v_in_m_s, double expected_contacts) const;

  int panels() const { return panels_; }
  int refused() const { return refused_; }
  long steps() const { return steps_; }  // of the panels' integrations, accepted or not

 private:
  static constexpr int kFields = 11;
  struct Panel {
    double s_lo = 0.0, s_hi = 0.0;  // ln v
    bool accepted = false;
    std::array<std::array<double, kNodes>, kFields> coef{};
  };
  const Panel* Covering(double s) const;
  void Build(double v_hi);
  ContactRun Tight(double v);
  ContactRun Evaluate(const Panel& p, double v) const;

  Integrate integrate_;
  ContactRunOptions tight_;
  double mass_kg_, rest_speed_m_s_, stuck_restitution_, rel_tolerance_;
  std::vector<Panel> panels_list_;
  int panels_ = 0, refused_ = 0;
  long steps_ = 0;
};

}  // namespace bouncecal

// bouncecal/physics/contact_dynamics.hpp — a contact law prepared for one parameter vector and
// body: what the contact integrator evaluates, in double and in forward-sensitivity arithmetic.
//
//   std::unique_ptr<ContactDynamics> dyn = law->Dynamics(p, body);   // constants prepared once
//   double f = dyn->Force(delta_m, delta_dot_m_s, state);            // N, on its branch
//
// Every built-in law writes its force and state rate once, as functions templated on the
// scalar type (src/physics/laws/law_base.hpp); the same code runs in double and in
// SensitivityJet, a ceres::Jet whose derivative slots are the directions of forward
// sensitivities: slot j < P is the law's parameter p_j (the prepared constants carry their
// p-derivatives), the remaining slots are free for the caller (the integrator uses slot P for
// the impact speed). The user expression law (muParser, double only) differences itself.
//
// Conventions: delta >= 0 (the integrator clamps it unless ContinuesBelowZero), rate =
// delta_dot (> 0 loading); "branch"
// selects the side of the law's switch (Walton-Braun: loading = true) so that every trial point
// of an integrator step stays on the branch the step started on (the integrator locates sign
// changes of Switch and restarts on the other branch). Laws without a switch ignore it.
#pragma once

#include <ceres/jet.h>

#include <cmath>

#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal {

// Directions of forward sensitivities: the law's parameters (at most
// kMaxSensitivityParameters) and the contact's impact speed.
inline constexpr int kSensitivityDirections = 8;
inline constexpr int kMaxSensitivityParameters = kSensitivityDirections - 1;
using SensitivityJet = ceres::Jet<double, kSensitivityDirections>;

// Hertz's force with Hunt-Crossley damping, F = k delta^(3/2) (1 + alpha delta'), and 0 where
// delta <= 0 or the factor 1 + alpha delta' <= 0 (N; delta in m, delta' in m/s). One
// definition for the law and for the integrator, which inlines it into its stages
// (ContactDynamics::InlineHertzDamper): the same operations in the same order either way.
struct HertzDamper {
  double k = 0.0;      // N/m^1.5
  double alpha = 0.0;  // s/m
  double operator()(double delta_m, double delta_dot_m_s) const {
    if (!(delta_m > 0.0)) return 0.0;
    const double factor = 1.0 + alpha * delta_dot_m_s;
    if (!(factor > 0.0)) return 0.0;
    return k * (delta_m * std::sqrt(delta_m)) * factor;
  }
};

class ContactDynamics {
 public:
  virtual ~ContactDynamics() = default;

  virtual int StateSize() const = 0;
  virtual int ParameterCount() const = 0;
  virtual ContactEnd EndRule() const = 0;
  // The force is a smooth function of delta^(1/q) and delta' near delta = 0 (q = 4 for Tsuji's
  // delta^(1/4), 2 for Hertz's delta^(3/2), 1 for laws smooth in delta). The integrator takes
  // u = delta^(1/q) as its independent variable where the overlap is small.
  virtual int OverlapRoot() const { return 1; }
  // The force formula continues smoothly to delta < 0 (laws linear in delta): the integrator
  // then passes the overlap through unclamped past the end of the contact, so the step that
  // crosses the end sees no kink. Otherwise it passes max(delta, 0) (F(0, delta') beyond).
  virtual bool ContinuesBelowZero() const { return false; }
  virtual bool HasSwitch() const { return false; }
  // Internal state at first touch; independent of p and of the impact speed (sensitivities
  // assume so). Default: zeros.
  virtual void InitialState(double* state) const;
  // Size of state variable i for error control, given the contact's length scale (m) and
  // energy scale (J): the integrator controls errors of state[i] / scale.
  virtual double StateScale(int i, double length_m, double energy_j) const;

  // Normal force on the ball (N, positive = repulsive) on the given branch.
  virtual double ForceOnBranch(double delta_m, double delta_dot_m_s, const double* state,
                               bool branch) const = 0;
  virtual SensitivityJet ForceOnBranch(const SensitivityJet& delta_m,
                                       const SensitivityJet& delta_dot_m_s,
                                       const SensitivityJet* state, bool branch) const = 0;
  // d(state)/dt; laws without state need not override.
  virtual void StateRate(double delta_m, double delta_dot_m_s, const double* state,
                         double* rate) const;
  virtual void StateRate(const SensitivityJet& delta_m, const SensitivityJet& delta_dot_m_s,
                         const SensitivityJet* state, SensitivityJet* rate) const;
  // Laws whose force switches discontinuously report the switch as the sign change of this
  // function (Walton-Braun: delta'). Default +1 (no switch).
  virtual double Switch(double delta_m, double delta_dot_m_s, const double* state) const;
  virtual SensitivityJet Switch(const SensitivityJet& delta_m, const SensitivityJet& delta_dot_m_s,
                                const SensitivityJet* state) const;

  // The law's memory update at a located switch (Walton-Braun hysteresis: the peak overlap is
  // recorded when loading turns to unloading); the state may jump there. Default: none.
  virtual void AtSwitch(double delta_m, double* state) const;
  virtual void AtSwitch(const SensitivityJet& delta_m, SensitivityJet* state) const;

  // Energy stored elastically at this overlap and state (recoverable part), J.
  virtual double ElasticEnergy(double delta_m, const double* state) const = 0;
  // Energy held in internal buffers (Jiang-Liu w_r), J; 0 for most laws.
  virtual double InternalEnergy(const double* state) const;
  // The elastic energy at the initial state as a power law, ElasticEnergy(delta) =
  // coefficient * delta^exponent, when it is one (Hertz: 0.4 k delta^2.5): the contact-time
  // estimate then solves ElasticEnergy(delta_max) = m v^2 / 2 in closed form instead of by a
  // search. Default: false (not known to be a power law).
  virtual bool ElasticPowerLaw(double* coefficient, double* exponent) const;
  // The force as the contact integrator may inline it into its stages, when the law's force is
  // this closed form in double (no state, no switch): the Hunt-Crossley family at n = 1.5.
  // Default: false.
  virtual bool InlineHertzDamper(HertzDamper* form) const;

  // The force on the branch the state is on.
  double Force(double delta_m, double delta_dot_m_s, const double* state) const {
    return ForceOnBranch(delta_m, delta_dot_m_s, state,
                         Switch(delta_m, delta_dot_m_s, state) > 0.0);
  }
};

}  // namespace bouncecal

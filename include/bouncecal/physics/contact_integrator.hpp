// bouncecal/physics/contact_integrator.hpp — one contact of the ball with the surface, integrated.
//
// The simulator's inner loop (simulator.hpp wraps it). The ball's downward displacement y
// (m, 0 at first touch) obeys m y'' = m g - F(delta, delta', state) with delta = y - z the
// overlap; z is the plate's displacement when the surface is a mass on a spring and dashpot
// (M z'' = F - K z - C z', Surface::kSpringMass), else 0. The law's internal state obeys its
// own ODEs (ContactDynamics::StateRate). Gravity during the contact is included (g_m_s2); the
// laws' closed forms neglect it, so pass g_m_s2 = 0 to compare with them.
//
// Integration: an embedded Runge-Kutta pair with its continuous extension and a PI step
// controller — DOP853 (order 8, dense output of order 7: physics/dop853.hpp) at
// rel_tolerance <= 1e-7, where it needs a third of the steps, the Dormand-Prince 5(4) pair
// (physics/dopri5.hpp) above (ContactRunOptions::method forces either) — on variables scaled
// to the contact's natural units (time by a contact-time estimate t_c, velocity by v_in,
// overlap by v_in t_c, energy by m v_in^2 / 2, law state by ContactDynamics::StateScale); the
// error of a step is measured over the scaled variables against abs_tolerance + s
// rel_tolerance max(1, |x_i|) — absolute control in the contact's own units (s = 1/4 for
// dopri5, 0.15 for DOP853: every law's errors at a given rel_tolerance stay at or below those
// of the previous integrator: bench_simulate). The first step is a fixed fraction of the
// contact (for dopri5 0.5 (rel_tolerance/4)^(1/5) of it), not a blind guess. Errors of e and
// of the contact time fall in proportion to rel_tolerance (tests/contact_integrator_test.cpp:
// at most about 2-3 rel_tolerance per contact for every law).
// Three phases, so that every step sees a smooth solution:
//   - approach: forces like delta^(3/2) and delta^(1/4) delta' are not smooth in time at first
//     touch (t^(1/4): step sizes collapse there). The law says in which root of delta it is
//     smooth (ContactDynamics::OverlapRoot q); while delta' > 0.7 v_in the independent variable
//     is u = (delta / L)^(1/q) (time becomes a state variable, dt/du = q u^(q-1) L / delta').
//   - middle: time is the independent variable around the maximum compression; events are
//     LOCATED inside accepted steps on the dense output (Illinois, 1e-14 relative in time):
//     sign changes of the law's Switch (Walton-Braun's loading -> unloading branch: every trial
//     point of a step is evaluated on the branch the step started on, the switch is located,
//     the step cut there and the integrator restarted on the other branch) and, for laws smooth
//     in delta (q = 1) or ending at F = 0, the contact end.
//   - exit: for laws with q > 1 ending at delta = 0, once delta' < 0 and delta < 0.7 of its peak
//     (0.5 with DOP853 for q = 2), u again, integrated down to u = 0 exactly: the end is the end of
//     the last step (no root finding, no step across the singular end). If delta' fades (a
//     creeping, overdamped ball) the integrator returns to time, where the stuck tests live.
// Forward sensitivities (RunContact with a ContactSensitivity): the same integration in
// SensitivityJet arithmetic (contact_dynamics.hpp) with the step sequence of the values, so the
// derivatives are those of the computed solution; event times and phase changes carry their
// own derivatives (implicit function theorem), and so do the jumps at branch switches.
//
//   ContactRun r = RunContact(law, p, body, 1.98, 9.8, nullptr, ContactRunOptions{});
//   if (r.end == ContactRun::End::kSeparated) ... r.v_out_m_s, r.contact_s
//
// Common mistakes: y and delta differ only with a compliant plate; v_out is the ball's
// upward speed at separation, which for kForceZero laws happens at delta > 0 (the ball is
// then still below the undeformed surface, separation_depth_m > 0).
#pragma once

#include <array>
#include <span>
#include <string>

#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal {

// The plate of a compliant surface: mass on a spring and a dashpot, at rest at first touch.
struct PlateModel {
  double mass_kg = 0.0;
  double stiffness_n_m = 0.0;
  double damping_n_s_m = 0.0;
};

// The Runge-Kutta pair a contact is integrated with. kAuto: DOP853 (order 8,
// physics/dop853.hpp) at rel_tolerance <= 1e-7, where it takes fewer right-hand-side
// evaluations for the same error, dopri5 (order 5) above (tools/bench_simulate measures both).
enum class ContactMethod { kAuto, kDopri5, kDop853 };

struct ContactRunOptions {
  double rel_tolerance = 1e-9;   // on the scaled variables (see above)
  double abs_tolerance = 1e-12;  // on the scaled variables
  int max_steps = 200000;        // attempted steps (accepted + rejected) per contact
  // The ball counts as stuck when its remaining mechanical energy in the contact (kinetic +
  // potential relative to first touch + elastic + plate) could no longer send it off faster
  // than this speed (m/s).
  double stuck_speed_m_s = 0.0;
  // ... or when the contact lasts longer than this many contact-time estimates.
  double max_contact_time_factor = 1e5;
  std::string label = "contact";  // names the law in messages
  ContactMethod method = ContactMethod::kAuto;
};

struct ContactRun {
  enum class End {
    kSeparated,  // the ball left the surface
    kStuck,      // no rebound: overdamped, or held in contact by gravity
    kStepLimit,  // max_steps reached (reported, never a hang)
  };
  End end = End::kSeparated;
  std::string detail;               // why it stuck / hit the step limit
  double v_out_m_s = 0.0;           // ball's upward speed at separation (0 if stuck)
  double contact_s = 0.0;           // first touch to separation (or to the stop)
  double separation_depth_m = 0.0;  // ball below its first-touch height at separation
  double peak_overlap_m = 0.0;
  double peak_force_n = 0.0;          // max over accepted step ends and the overlap maximum
  double work_j = 0.0;                // energy the ball gave to the contact: integral of F y' dt
  double elastic_end_j = 0.0;         // law's elastic energy left at the end (lost if separated)
  double plate_end_j = 0.0;           // plate kinetic + spring energy at the end
  double internal_end_j = 0.0;        // law's internal energy at the end (Jiang-Liu w_r)
  double ball_energy_end_j = 0.0;     // ball kinetic + potential (rel. first touch) at the end
  double contact_time_scale_s = 0.0;  // the t_c estimate used for scaling
  int steps = 0;                      // attempted steps (0 for closed form)
  int rejected = 0;                   // of which rejected by the error control
  int switches = 0;                   // located Switch sign changes
  bool closed_form = false;
};

// Derivatives of a separated contact's outcome: direction j < P (the law's parameter count) is
// p_j, direction P the impact speed v_in; later directions are 0.
struct ContactSensitivity {
  std::array<double, kSensitivityDirections> v_out{};               // d v_out / d theta_j
  std::array<double, kSensitivityDirections> contact_s{};           // d contact_s / d theta_j
  std::array<double, kSensitivityDirections> separation_depth_m{};  // d depth / d theta_j
};

// An a-priori contact-time estimate (s) for scaling and decisions: the law's ContactTime
// closed form when it has one, else 3 delta_max / v_in with delta_max from the elastic energy
// (ElasticEnergy(delta_max) = m v_in^2 / 2, solved in closed form when the law's elastic energy
// is a power law (ContactDynamics::ElasticPowerLaw), else by a search; exact factor: pi for
// linear, 2.94 for Hertz).
double EstimateContactTime(const ContactLaw& law, std::span<const double> p,
                           const ContactDynamics& dynamics, const ContactBody& body,
                           double v_in_m_s);

// Integrates one contact from first touch at speed v_in_m_s > 0 (downward). plate may be null
// (rigid surface). Never throws for a valid law/parameter set; failures are reported in end.
// With sensitivity non-null (and at most kMaxSensitivityParameters parameters) the derivatives
// of the outcome are computed too (for a separated contact; zeros otherwise).
ContactRun RunContact(const ContactDynamics& dynamics, const ContactBody& body,
                      double contact_time_scale_s, double v_in_m_s, double g_m_s2,
                      const PlateModel* plate, const ContactRunOptions& options,
                      ContactSensitivity* sensitivity = nullptr);

// Convenience: prepares the law's dynamics and its contact-time estimate, then integrates.
ContactRun RunContact(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                      double v_in_m_s, double g_m_s2, const PlateModel* plate,
                      const ContactRunOptions& options);

}  // namespace bouncecal

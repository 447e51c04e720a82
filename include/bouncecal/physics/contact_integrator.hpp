// bouncecal/physics/contact_integrator.hpp — one contact of the ball with the surface, integrated.
//
// The simulator's inner loop (simulator.hpp wraps it). The ball's downward displacement y
// (m, 0 at first touch) obeys m y'' = m g - F(delta, delta', state) with delta = y - z the
// overlap; z is the plate's displacement when the surface is a mass on a spring and dashpot
// (M z'' = F - K z - C z', Surface::kSpringMass), else 0. The law's internal state obeys its
// own ODEs (ContactLaw::StateRate). Gravity during the contact is included (g_m_s2); the laws'
// closed forms neglect it, so pass g_m_s2 = 0 to compare with them.
//
// Integration: Boost.Odeint runge_kutta_dopri5 under its controlled stepper, with the
// dopri5 dense output (calc_state) used to LOCATE events inside an accepted step:
//   - the contact end (delta = 0, or F = 0 for laws whose EndRule() is kForceZero),
//   - sign changes of the law's SwitchFunction (Walton-Braun's loading -> unloading branch).
// A switch is never stepped over: every trial point of a step is evaluated on the branch the
// step started on (ContactLaw::ForceOnBranch continues that branch smoothly past the switch),
// so the step and its dense output stay smooth; the sign change is located on the dense
// output (Illinois/bisection, 1e-14 relative in time), the step is cut there and the
// integrator restarts on the other branch. The end event is continuous (the force is
// extended past delta = 0 by F(0, delta')), so it is located the same way.
// Variables are scaled to the contact's natural units before integration: time by a
// contact-time estimate t_c (closed form if the law has one, else from the elastic energy),
// velocity by v_in, overlap by v_in t_c, energy by m v_in^2 / 2; tolerances apply to these.
//
//   ContactRun r = RunContact(law, p, body, 1.98, 9.8, nullptr, ContactRunOptions{});
//   if (r.end == ContactRun::End::kSeparated) ... r.v_out_m_s, r.contact_s
//
// Common mistakes: y and delta differ only with a compliant plate; v_out is the ball's
// upward speed at separation, which for kForceZero laws happens at delta > 0 (the ball is
// then still below the undeformed surface, separation_depth_m > 0).
#pragma once

#include <span>
#include <string>

#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal {

// The plate of a compliant surface: mass on a spring and a dashpot, at rest at first touch.
struct PlateModel {
  double mass_kg = 0.0;
  double stiffness_n_m = 0.0;
  double damping_n_s_m = 0.0;
};

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
  int switches = 0;                   // located SwitchFunction sign changes
  bool closed_form = false;
};

// An a-priori contact-time estimate (s) for scaling and decisions: the law's ContactTime
// closed form when it has one, else 3 delta_max / v_in with delta_max from the elastic energy
// (ElasticEnergy(delta_max) = m v_in^2 / 2; exact factor: pi for linear, 2.94 for Hertz).
double EstimateContactTime(const ContactLaw& law, std::span<const double> p,
                           const ContactBody& body, double v_in_m_s);

// Integrates one contact from first touch at speed v_in_m_s > 0 (downward). plate may be null
// (rigid surface). Never throws for a valid law/parameter set; failures are reported in end.
ContactRun RunContact(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                      double v_in_m_s, double g_m_s2, const PlateModel* plate,
                      const ContactRunOptions& options);

}  // namespace bouncecal

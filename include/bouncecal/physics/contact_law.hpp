// bouncecal/physics/contact_law.hpp — the interface every normal contact law implements.
//
// A contact law maps the overlap delta >= 0 (m), its rate delta_dot (m/s, > 0 while the ball
// moves into the surface) and an optional internal state to the normal force on the ball
// (N, positive = repulsive). Laws are small immutable objects created by the registry
// (law_registry.hpp) from a name and a parameter map; they hold no global state, so every
// thread or job creates its own.
//
//   LawSpec spec{"hertz-tsuji", {{"k", 1e9}, {"e", 0.8}}, ""};
//   auto law = CreateLaw(spec, scene);                                  // law_registry.hpp
//   ContactBody body = BodyFromScene(scene);                            // m* = m, R* = R
//   std::vector<double> p = law->ParameterValues();
//   double e = law->Restitution(p, body, 1.5).value();                 // closed form, if any
//   auto dynamics = law->Dynamics(p, body);   // force, state rate, energies (contact_dynamics.hpp)
//
// Conventions (docs/physics.md §3): m* is the effective mass, R* the effective radius; a ball on a
// rigid wall has m* = m, R* = R. Closed forms neglect gravity during the contact (it is
// included by the simulator). Parameters are passed as a flat vector in the order of
// Parameters(), so the fitter can hand Ceres a raw pointer; names and units live in the specs.
// A law's name, formula, source, end rule and the list of its closed forms are the columns of
// its row in the registry table (src/physics/law_registry.cpp), not code in the law.
//
// Common mistakes: stiffness k is in the law's own units (N/m for linear laws, N/m^1.5 for
// Hertz-type laws); the contact ends at delta = 0 unless EndRule() says kForceZero; the
// dynamics object borrows the law (keep the law alive while it is used).
#pragma once

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace bouncecal {

// The two bodies in contact, reduced to what a normal contact law needs.
struct ContactBody {
  double mass_kg = 0.0;          // effective (reduced) mass m*
  double radius_m = 0.0;         // effective radius R*
  double ball_mass_kg = 0.0;     // grain mass (Jiang-Liu eqs. 37-41 use it)
  double ball_diameter_m = 0.0;  // grain diameter d

  static ContactBody BallOnRigidWall(double mass_kg, double radius_m) {
    return {mass_kg, radius_m, mass_kg, 2.0 * radius_m};
  }
};

struct ParameterSpec {
  std::string name;         // registry key, as typed by users: "k", "gamma", "A"
  std::string unit;         // "N/m", "N/m^1.5", "s", "1"
  std::string description;  // one line
  double lower = 0.0;       // physical bounds, inclusive; the fitter uses them
  double upper = 0.0;
  double default_value = 0.0;
  bool damping = false;  // fitted by default; others (stiffness) are held unless freed
};

// When a contact ends.
enum class ContactEnd {
  kOverlapZero,  // delta returns to 0 (force may turn attractive before; it is kept)
  kForceZero,    // the repulsive force reaches 0 (the ball detaches before delta = 0)
};

// Closed-form outcome of a single contact starting at delta = 0 with speed v_in.
struct ContactOutcome {
  double restitution = 0.0;  // v_out / v_in
  double contact_time_s = 0.0;
  double peak_overlap_m = 0.0;
  double peak_force_n = 0.0;
  double end_overlap_m = 0.0;  // overlap when the contact ends (> 0 for kForceZero laws)
  bool stuck = false;          // the ball never leaves (overdamped): restitution 0, time inf
};

class ContactDynamics;  // contact_dynamics.hpp

class ContactLaw {
 public:
  virtual ~ContactLaw() = default;

  // --- identity and parameters (name, formula, source, end rule: the law's registry row) ----
  virtual std::string Name() const = 0;     // registry name, e.g. "hertz-tsuji"
  virtual std::string Formula() const = 0;  // "F = k d^1.5 + eta d^0.25 d'", one line
  virtual std::string Source() const = 0;   // paper + equation
  virtual const std::vector<ParameterSpec>& Parameters() const = 0;
  // Values the law was created with, in the order of Parameters().
  virtual std::vector<double> ParameterValues() const = 0;
  int ParameterIndex(const std::string& name) const;  // -1 if unknown
  // Checks a full parameter vector for this body (bounds, finiteness, combinations).
  // The message names the parameter, its value and the rule.
  virtual bool IsValid(std::span<const double> p, const ContactBody& body,
                       std::string* error) const;
  virtual ContactEnd EndRule() const = 0;
  // Number of internal state variables (Jiang-Liu relaxation energy, hysteresis memory...).
  virtual int StateSize() const = 0;

  // --- dynamics ------------------------------------------------------------------------------
  // The law prepared for one parameter vector and body: its per-contact constants computed
  // once (Hertz-Tsuji's eta = alpha(e) sqrt(m* k), Jiang-Liu's a and tau), the force, the state
  // rate, the energies, and their derivatives for forward sensitivities. p must pass IsValid.
  virtual std::unique_ptr<ContactDynamics> Dynamics(std::span<const double> p,
                                                    const ContactBody& body) const = 0;

  // --- closed forms, where they exist (listed by ClosedForms(), a column of the row) ---------
  // Restitution e(v_in) and contact time for a contact starting at speed v_in (no gravity).
  virtual std::optional<double> Restitution(std::span<const double> p, const ContactBody& body,
                                            double v_in_m_s) const;
  virtual std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                            double v_in_m_s) const;
  // Full closed-form contact (linear laws): the simulator uses it instead of integrating.
  virtual std::optional<ContactOutcome> SolveContact(std::span<const double> p,
                                                     const ContactBody& body,
                                                     double v_in_m_s) const;
  // Inverse map: the parameter vector p with its damping parameter(s) set so that
  // e(v_in) = e. Seeds fits and serves as a test oracle.
  virtual std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                                   const ContactBody& body,
                                                                   double e, double v_in_m_s) const;
  // e(v_in) and de/dp_i (same order as Parameters()), analytic or automatic; false where the
  // law has no closed form. The fitter uses it for exact Jacobians.
  virtual bool RestitutionGradient(std::span<const double> p, const ContactBody& body,
                                   double v_in_m_s, double* e, double* de_dp) const;
  // Names of the closed forms this law provides ("restitution", "contact_time",
  // "solve_contact", "damping_for_restitution", "restitution_gradient"), for `bouncecal laws`.
  virtual std::vector<std::string> ClosedForms() const = 0;
};

}  // namespace bouncecal

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
//
// Conventions (PHYSICS.md §3): m* is the effective mass, R* the effective radius; a ball on a
// rigid wall has m* = m, R* = R. Closed forms neglect gravity during the contact (it is
// included by the simulator). Parameters are passed as a flat vector in the order of
// Parameters(), so the fitter can hand Ceres a raw pointer; names and units live in the specs.
//
// Common mistakes: stiffness k is in the law's own units (N/m for linear laws, N/m^1.5 for
// Hertz-type laws); the contact ends at delta = 0 unless EndRule() says kForceZero.
#pragma once

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

class ContactLaw {
 public:
  virtual ~ContactLaw() = default;

  // --- identity and parameters -------------------------------------------------------------
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

  // --- dynamics -----------------------------------------------------------------------------
  // Constants derived from (p, body) that a law would otherwise recompute at every force
  // evaluation (Hertz-Tsuji's eta = alpha(e) sqrt(m* k), alpha from a table). The integrator
  // calls PrepareParameters once per contact and then passes the EXTENDED vector
  // [p..., prepared...] (p.size() == Parameters().size() + PreparedSize()) to Force,
  // ForceOnBranch, SwitchFunction and StateRate; every other caller passes plain p. Laws
  // that prepare must therefore accept both sizes (use the prepared values when present).
  virtual int PreparedSize() const { return 0; }
  virtual void PrepareParameters(std::span<const double> /*p*/, const ContactBody& /*body*/,
                                 double* /*prepared*/) const {}
  virtual ContactEnd EndRule() const { return ContactEnd::kOverlapZero; }
  // Number of internal state variables (Jiang-Liu relaxation energy, hysteresis memory...).
  virtual int StateSize() const { return 0; }
  // Internal state at first touch (delta = 0, delta_dot = v_in > 0).
  virtual void InitialState(std::span<const double> p, const ContactBody& body, double v_in_m_s,
                            double* state) const;
  // Normal force on the ball, N, positive = repulsive.
  virtual double Force(std::span<const double> p, const ContactBody& body, double delta_m,
                       double delta_dot_m_s, const double* state) const = 0;
  // d(state)/dt. Laws with StateSize() == 0 need not override.
  virtual void StateRate(std::span<const double> p, const ContactBody& body, double delta_m,
                         double delta_dot_m_s, const double* state, double* rate) const;
  // Laws whose force switches discontinuously (loading/unloading branch) report the switch as
  // an event the integrator must locate: the simulator stops the step at sign changes of
  // SwitchFunction. Default: none (returns +1).
  virtual double SwitchFunction(std::span<const double> p, const ContactBody& body, double delta_m,
                                double delta_dot_m_s, const double* state) const;
  // The force on one side of the switch, continued smoothly past it: positive_branch selects
  // the branch where SwitchFunction > 0. An adaptive integrator must evaluate every trial point
  // of a step on the branch the step started on (else its error control rejects every step that
  // straddles the jump and the step size collapses), then locate the sign change of
  // SwitchFunction on the dense output and restart there on the other branch.
  // Default: Force (laws without a discontinuity).
  virtual double ForceOnBranch(std::span<const double> p, const ContactBody& body, double delta_m,
                               double delta_dot_m_s, const double* state,
                               bool positive_branch) const;

  // --- energy bookkeeping (J) ---------------------------------------------------------------
  // Energy stored elastically at this overlap and state (recoverable part).
  virtual double ElasticEnergy(std::span<const double> p, const ContactBody& body, double delta_m,
                               const double* state) const = 0;
  // Energy held in internal buffers (Jiang-Liu w_r); 0 for most laws.
  virtual double InternalEnergy(std::span<const double> p, const ContactBody& body, double delta_m,
                                const double* state) const;

  // --- closed forms, where they exist --------------------------------------------------------
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
  virtual std::vector<std::string> ClosedForms() const { return {}; }
};

}  // namespace bouncecal

// bouncecal/export/native_law.hpp — a DEM simulator's own normal contact force, as bouncecal
// evaluates it, so an exported mapping can be checked before the simulator runs.
//
// Each target simulator offers a few native normal laws (LAMMPS `granular hooke|hertz` with
// `damping velocity|viscoelastic|tsuji`, LIGGGHTS `hooke/stiffness`, `hertz`, `hertz/stiffness`,
// Yade `ViscElMat`, `MindlinPhys`). Written in bouncecal's units they are three forms:
//
//   kLinear:            F = k d + c d'                     k N/m,     c N*s/m
//   kHertzTsuji:        F = k d^1.5 + a sqrt(m* k) d^0.25 d'   k N/m^1.5, a (1) = Tsuji's alpha
//   kHertzViscoelastic: F = k (d^1.5 + 1.5 A d^0.5 d')     k N/m^1.5, A s
//
// and whether the simulator clips an attractive total force to 0 (Yade does, LAMMPS and
// LIGGGHTS by default do not): with clipping the contact effectively ends when F reaches 0.
// NativeModel is a ContactLaw, so the bouncecal integrator (SimulateContact) gives its e(v) and
// contact time exactly; FixedStepContact replays the simulators' own time stepping
// (velocity Verlet / leapfrog: the force at step n uses the position x_n and the half-step
// velocity v_(n-1/2); LAMMPS' fix nve, LIGGGHTS' and Yade's NewtonIntegrator are all this
// scheme) to show what a time step costs in e.
//
//   NativeModel m(NativeForm::kLinear, /*clip=*/false, k, c);
//   double e = m.RestitutionAt(body, 1.5);                 // adaptive, exact to ~1e-9
//   double err = MaxTimeStepError(m, body, {0.3, 2.0}, 1e-7, 9.8);
#pragma once

#include <string>
#include <vector>

#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/pointwise_law.hpp"

namespace bouncecal {

enum class NativeForm { kLinear, kHertzTsuji, kHertzViscoelastic };
const char* NativeFormName(NativeForm form);  // "linear", "hertz_tsuji", "hertz_viscoelastic"

class NativeModel final : public PointwiseContactLaw {
 public:
  NativeModel(NativeForm form, bool clip, double stiffness, double damping);

  NativeForm form() const { return form_; }
  bool clip() const { return clip_; }
  double stiffness() const { return values_[0]; }
  double damping() const { return values_[1]; }

  std::string Name() const override;
  std::string Formula() const override;
  std::string Source() const override;
  const std::vector<ParameterSpec>& Parameters() const override { return specs_; }
  std::vector<double> ParameterValues() const override { return values_; }
  ContactEnd EndRule() const override;
  double Force(std::span<const double> p, const ContactBody& body, double delta_m,
               double delta_dot_m_s, const double* state) const override;
  double ElasticEnergy(std::span<const double> p, const ContactBody& body, double delta_m,
                       const double* state) const override;

  // e and contact time of one gravity-free contact at v_in (bouncecal's adaptive integrator).
  double RestitutionAt(const ContactBody& body, double v_in_m_s) const;
  double ContactTimeAt(const ContactBody& body, double v_in_m_s) const;

 private:
  NativeForm form_;
  bool clip_;
  std::vector<ParameterSpec> specs_;
  std::vector<double> values_;
};

// One contact stepped as the simulators step it (see above), gravity g included, starting
// phase * dt before first touch (phase in [0, 1)). Returns e = v_out / v_in, both taken at the
// wall level from the flight on either side (as the exported impacts.csv does).
double FixedStepRestitution(const NativeModel& model, const ContactBody& body, double v_in_m_s,
                            double dt_s, double g_m_s2, double phase);
// The largest |e(fixed step) - e(adaptive, same gravity)| over 16 starting phases and the
// given speeds.
double MaxTimeStepError(const NativeModel& model, const ContactBody& body,
                        const std::vector<double>& speeds_m_s, double dt_s, double g_m_s2);

}  // namespace bouncecal

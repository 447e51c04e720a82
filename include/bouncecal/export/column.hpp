// bouncecal/export/column.hpp — seed 003's granular column collapse (Fei et al. 2016) as a scene
// for the exporters: geometry, beads, contacts and time step, resolved to numbers before any deck
// is written.
//
// The experiment (docs/physics.md §5, docs/column.md): a box 400 x 200 x 200 mm (x along the
// run-out, y across, z up), a gate 100 mm from the left wall, behind it a column 180 mm high,
// 100 mm long and 200 mm deep (aspect ratio a = 1.8) of ceramic beads (d normal within
// 4.9-5.9 mm, rho 2200 kg/m^3, E 5.5 GPa, mu 0.38), sandpaper on the floor; the gate is pulled
// and the column collapses, at rest by ~0.5 s. The scene keeps the box and the column at the
// paper's size (so run-out, profiles and times compare with the paper in mm and s) and coarsens
// the beads: `scale` S divides every bead diameter by S, so the column holds ~25167 S^3 beads
// (`particles` N sets S = (N / 25167)^(1/3)). The beads are poured (placed at random, loose)
// behind the gate (written to a file both simulators read, so LAMMPS and Yade start from the same
// state), settle under gravity, are trimmed at the column height, and the gate is removed.
//
// Contacts are the paper's Hertz-Mindlin law (eq. 12) with Tsuji's normal damping, whose
// restitution depends on the damping alpha alone (not on sizes or masses): the fitted law is
// mapped onto the target with MapLaw (mapping.hpp), exactly as for the bounce deck, and the
// native law's alpha (or its restitution, turned into alpha) is carried to every bead pair.
//
//   ColumnOptions o; o.scale = 1.0 / 3.0;
//   ColumnPlan p = PlanColumn(o, ExportTarget::kLammps, bead_bead, bead_wall);  // throws
//   std::string data = ColumnBeadsText(p);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bouncecal/export/mapping.hpp"

namespace bouncecal {

// Seed 003 (Fei et al. 2016, section 4): the set-up the column scene reproduces, SI units.
struct ColumnPaper {
  static constexpr int kBeads = 25167;  // the paper's DEM
  static constexpr double kBoxLength_m = 0.4, kBoxWidth_m = 0.2, kBoxHeight_m = 0.2;
  static constexpr double kColumnLength_m = 0.1, kColumnHeight_m = 0.18;  // a = 1.8
  static constexpr double kDiameterMin_m = 4.9e-3, kDiameterMax_m = 5.9e-3;
  static constexpr double kDensity_kg_m3 = 2200.0, kYoungs_pa = 5.5e9;
  static constexpr double kFriction = 0.38;         // tan of the 21 deg repose angle
  static constexpr double kReposeAngle_deg = 21.0;  // 10 pourings, 18-22 deg
  static constexpr double kFrameInterval_s = 0.04;  // the 25 fps camera
  static constexpr double kRestBy_s = 0.52;         // last frame of the paper's fig. 7
};

struct ColumnOptions {
  double scale = 1.0;  // bead diameters divided by scale; ~25167 scale^3 beads
  int particles = 0;   // > 0: beads in the column instead, scale = (particles / 25167)^(1/3)
  // Pairwise restitution instead of the fits' (bead-bead and bead-wall); 0 = the fits'.
  double restitution = 0.0;
  std::string wall_params;  // parameter file of the bead-wall contact; "" = bead-bead's
  // mu_r of the paper's eq. 13, which gives no value: the beads' half relative diameter spread,
  // (5.9 - 4.9) / (2 x 5.4) = 0.093, the largest offset of the contact normal (in radii) that an
  // ovality as large as that spread would give (rolling friction as a stand-in for shape:
  // Wensrich & Katterfeld, Powder Technol. 217 (2012) 409); an upper estimate (docs/column.md).
  double rolling_friction = (ColumnPaper::kDiameterMax_m - ColumnPaper::kDiameterMin_m) /
                            (ColumnPaper::kDiameterMax_m + ColumnPaper::kDiameterMin_m);
  double dt_e_error = 0.01;     // the time step is halved until its e error is below this
  double max_collapse_s = 2.0;  // the run stops at rest or after this long
  uint64_t seed = 3;            // bead sizes and pour positions
  int ranks = 1;                // MPI ranks (LAMMPS) or threads (Yade) the memory check assumes
  bool IsValid(std::string* error) const;
};

// seed 003 eq. 11 (after Jiang & Liu): q_phi from the friction angle phi (radians);
// 21 deg gives 0.452. NaN where 4 tan^2 phi > 1 (phi above 26.6 deg).
double QPhiFromFrictionAngle(double phi_rad);

// One contact class of the column (bead-bead, bead-floor sphere, bead-wall), every number the
// decks write.
struct ColumnContact {
  std::string name;       // "bead-bead", "bead-floor", "bead-wall"
  double restitution;     // e the native law gives this pair (gravity-free, any speed)
  double alpha;           // Tsuji alpha (F_d = alpha sqrt(m* k) d^1/4 d'), under the target's end
  double e_error;         // |e_native - e_fit| at the fit's speeds (mapping), or 0 when given
  double e_input_lammps;  // the e LAMMPS' damping tsuji polynomial turns into alpha
  double yade_betan;      // alpha / sqrt(6)
  double kn_pa;           // LAMMPS `hertz` kn: F = kn sqrt(R* d) d (= 4/3 E*)
  double kt_pa;  // LAMMPS `mindlin` kt: F_t = kt a xi (Yade's Kso rule, see column_contact)
  double tangential_damping_ratio;  // LAMMPS x_gamma_t: Yade's c_s / c_n
  double rolling_mu_lammps;         // LAMMPS mu_roll giving Yade's limit torque mu_r R_mean F_n
  double rolling_k_lammps;          // LAMMPS k_roll (N/m): torque stiffness k_r / R*^2
  double contact_time_s;            // at the column's largest impact speed, smallest pair
  double reduced_mass_kg, reduced_radius_m;
};

// A fit mapped for the column: the mapping (as the bounce deck states it) and its source file.
struct ColumnFit {
  std::string params_path;
  Mapping mapping;
  double restitution = 0.0;  // the native law's e (its middle over the fit's speeds)
  double e_error = 0.0;      // max |e_column - e_fit| over the fit's speeds
  std::vector<std::string> notes;
};

struct ColumnPlan {
  ExportTarget target = ExportTarget::kLammps;
  double scale = 1.0;
  double d_mean_m = 0.0, d_sigma_m = 0.0, d_min_m = 0.0, d_max_m = 0.0;
  double floor_diameter_m = 0.0;  // fixed spheres on the floor (the sandpaper)
  double column_height_m = ColumnPaper::kColumnHeight_m;
  double pour_top_m = 0.0;  // the pour's highest centre
  double pour_bottom_m = 0.0;
  double box_top_m = 0.0;  // the simulation box's top (the real box is open)
  int poured_beads = 0;    // beads poured (before the trim at the column height)
  int expected_beads = 0;  // ~ the paper's 25167 scale^3, after the trim
  int floor_spheres = 0;
  double rest_speed_m_s = 0.0;  // rms bead speed below which the beads are at rest
  double settle_min_s = 0.0;    // the pour's free fall to the column height
  double settle_max_s = 1.0;
  double max_collapse_s = 2.0;
  double dump_interval_s = 0.01;
  double time_step_s = 0.0;
  double time_step_e_error = 0.0;
  std::string time_step_choice;
  long settle_steps = 0, collapse_steps = 0, dump_every = 0;
  double memory_bytes = 0.0;  // estimated peak, all ranks
  double friction = ColumnPaper::kFriction, rolling_friction = 0.0, q_phi = 0.0;
  double rolling_stiffness_nm_rad = 0.0;  // k_r, every contact (Yade's krot)
  double poisson_ratio = 0.25, wall_youngs_pa = 0.0, wall_poisson = 0.0;
  double yade_wall_youngs_pa = 0.0;  // raised so Yade's R/2 wall convention gives LAMMPS' Kno
  ColumnFit bead_fit, wall_fit;
  ColumnContact bead_bead, bead_floor, bead_wall;
  uint64_t seed = 3;
  std::vector<std::string> notes;
};

// The column for a target from the bead-bead and bead-wall fits (wall = bead when the options
// name no wall file). Throws Error(kBadParameter) when the beads do not fit the column (fewer
// than three across its length) or the run would need more memory than the machine has.
ColumnPlan PlanColumn(const ColumnOptions& options, ExportTarget target, const ColumnFit& bead,
                      const ColumnFit& wall);

// The beads and floor spheres as "type diameter x y z" lines (type 1 bead, 2 floor), seeded.
struct ColumnSphere {
  int type;
  double diameter_m, x_m, y_m, z_m;
};
std::vector<ColumnSphere> ColumnSpheres(const ColumnPlan& plan);

// Physical memory of this machine, bytes (sysconf).
double MachineMemoryBytes();

}  // namespace bouncecal

// LAMMPS decks (bounce and packing) for the Debian 12 build ("29 Sep 2021 - Update 2").
//
// Keywords (LAMMPS GRANULAR package, docs of fix wall/gran and pair_style granular):
//   fix wall/gran granular hooke kn eta_n0 damping velocity    F = kn d - eta_n0 v_n
//   fix wall/gran granular hertz kn eta_n0 damping viscoelastic F = kn a d - eta_n0 a m* v_n,
//                                                             a = sqrt(R d), m* = m (wall)
//   fix wall/gran granular hertz kn e damping tsuji           F = kn a d - alpha(e) sqrt(m* kn a)
//   v_n
//                                                             with LAMMPS' alpha(e) polynomial
//   pair_style gran/hooke/history kn kt gamma_n gamma_t xmu dampflag   F = kn d - m* gamma_n v_n
// Units: `units si`. The wall is the plane z = 0; the sphere's mass is density * pi d^3 / 6.
#include <cmath>
#include <sstream>

#include "bouncecal/core/format.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {
namespace {

std::string WallLine(const DeckInput& in) {
  const Mapping& m = in.mapping;
  const auto& c = m.coefficients;
  std::ostringstream os;
  os << "fix wall all wall/gran granular ";
  if (m.form == NativeForm::kLinear) {
    os << "hooke " << FormatShortest(c.at("kn_n_m")) << " " << FormatShortest(c.at("damping_n_s_m"))
       << " damping velocity";
  } else if (m.form == NativeForm::kHertzViscoelastic) {
    os << "hertz " << FormatShortest(c.at("kn_pa")) << " " << FormatShortest(c.at("eta_n0_1_m_s"))
       << " damping viscoelastic";
  } else {
    os << "hertz " << FormatShortest(c.at("kn_pa")) << " " << FormatShortest(c.at("e_input"))
       << " damping tsuji";
  }
  os << " tangential linear_nohistory 0 0 zplane 0.0 NULL\n";
  return os.str();
}

}  // namespace

std::string LammpsBounceDeck(const DeckInput& in) {
  const double r = in.radius_m, z0 = r + in.release_height_m;
  std::ostringstream os;
  os << CommentBlock(in.comments, "# ");
  os << "# Run: lmp -in in.bounce   (-var steps N to shorten; run.sh does this and writes\n"
     << "# impacts.csv)\n\n";
  os << "units si\n"
     << "atom_style sphere\n"
     << "atom_modify map array\n"
     << "boundary f f f\n"
     << "comm_modify vel yes\n"
     << "region box block " << FormatShortest(-4 * r) << " " << FormatShortest(4 * r) << " "
     << FormatShortest(-4 * r) << " " << FormatShortest(4 * r) << " " << FormatShortest(-r) << " "
     << FormatShortest(z0 + 4 * r) << " units box\n"
     << "create_box 1 box\n"
     << "create_atoms 1 single 0 0 " << FormatShortest(z0) << " units box\n"
     << "set atom 1 diameter " << FormatShortest(2 * r) << " density "
     << FormatShortest(in.density_kg_m3) << "\n"
     << "velocity all set 0 0 0\n"
     << "pair_style none\n"
     << "fix integrate all nve/sphere\n"
     << "fix gravity all gravity " << FormatShortest(in.g_m_s2) << " vector 0 0 -1\n"
     << WallLine(in) << "timestep " << FormatShortest(in.time_step_s) << "\n"
     << "variable steps index " << in.steps << "\n"
     << "variable t equal time\n"
     << "variable z equal z[1]\n"
     << "variable vz equal vz[1]\n"
     << "fix trace all print " << in.trace_every
     << " \"${t},${z},${vz}\" file trace.csv screen no title \"t_s,z_m,vz_m_s\"\n"
     << "thermo " << std::max<long>(in.steps / 10, 1) << "\n"
     << "run ${steps}\n";
  return os.str();
}

std::string LammpsPackingDeck(const DeckInput& in) {
  // Seed 002's validation scene (docs/physics.md §1): k_n = k_s = 1e7 N/m, mu = 0.3, the fitted e.
  // gran/hooke/history damps with m* gamma_n: the same e needs gamma_n = 2 zeta sqrt(kn/m*),
  // m* = m/2 between spheres and m* = m against the walls.
  const PackingScene ps(in.packing_restitution);
  const double kn = ps.kn, mu = ps.mu, d = ps.d, rho = ps.rho, gn_pp = ps.gn_pp, gn_pw = ps.gn_pw;
  std::ostringstream os;
  os << CommentBlock(in.comments, "# ");
  os << "# Run: mpirun -np N lmp -in in.packing   (-var steps N, -var seed S)\n\n"
     << "units si\n"
     << "atom_style sphere\n"
     << "boundary f f f\n"
     << "newton off\n"
     << "comm_modify vel yes\n"
     << "# The pile settles at the bottom: split the ranks across x and y, never along z.\n"
     << "processors * * 1\n"
     << "region box block -0.105 0.105 -0.105 0.105 -0.001 0.25 units box\n"
     << "create_box 1 box\n"
     << "neighbor 0.002 bin\n"
     << "neigh_modify delay 0\n"
     << "# gamma_n (1/s): " << FormatShortest(gn_pp) << " between spheres, "
     << FormatShortest(gn_pw)
     << " against walls, both giving e = " << FormatShortest(in.packing_restitution) << "\n"
     << "pair_style gran/hooke/history " << FormatShortest(kn) << " " << FormatShortest(kn) << " "
     << FormatShortest(gn_pp) << " " << FormatShortest(0.5 * gn_pp) << " " << FormatShortest(mu)
     << " 1\n"
     << "pair_coeff * *\n"
     << "fix gravity all gravity " << FormatShortest(in.g_m_s2) << " vector 0 0 -1\n"
     << "fix integrate all nve/sphere\n"
     << "fix floor all wall/gran hooke/history " << FormatShortest(kn) << " " << FormatShortest(kn)
     << " " << FormatShortest(gn_pw) << " " << FormatShortest(0.5 * gn_pw) << " "
     << FormatShortest(mu) << " 1 zplane 0.0 NULL\n"
     << "fix side all wall/gran hooke/history " << FormatShortest(kn) << " " << FormatShortest(kn)
     << " " << FormatShortest(gn_pw) << " " << FormatShortest(0.5 * gn_pw) << " "
     << FormatShortest(mu) << " 1 zcylinder 0.1\n"
     << "# The hopper: the spheres start at rest on a jittered lattice (spacing 1.25 d) between\n"
     << "# 5 and 20 cm and fall together (fix pour of this version inserts one batch only).\n"
     << "region hopper cylinder z 0 0 0.094 0.05 0.2 units box\n"
     << "lattice sc " << FormatShortest(1.25 * d) << " origin 0.5 0.5 0.5\n"
     << "variable seed index 4767\n"
     << "create_atoms 1 region hopper subset " << in.options.packing_particles << " ${seed}\n"
     << "displace_atoms all random " << FormatShortest(0.07 * d) << " " << FormatShortest(0.07 * d)
     << " " << FormatShortest(0.07 * d) << " ${seed} units box\n"
     << "set group all diameter " << FormatShortest(d) << " density " << FormatShortest(rho) << "\n"
     << "velocity all set 0 0 0\n"
     << "timestep " << FormatShortest(in.time_step_s) << "\n"
     << "variable steps index " << in.steps << "\n"
     << "compute rke all erotate/sphere\n"
     << "thermo_style custom step atoms ke c_rke\n"
     << "thermo " << std::max<long>(in.steps / 20, 1) << "\n"
     << "run ${steps}\n"
     << "write_dump all custom packing.dump id x y z radius modify sort id\n";
  return os.str();
}

}  // namespace bouncecal::exporter

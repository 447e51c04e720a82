// LIGGGHTS decks (bounce and packing) for the Debian 12 build (LIGGGHTS-PUBLIC 3.8.0).
//
// Keywords (LIGGGHTS-PUBLIC docs of gran model hooke/stiffness, hertz, hertz/stiffness; the
// per-type-pair coefficients are `fix property/global NAME peratomtypepair 2 ...`):
//   model hooke/stiffness: F = k_n d - m* gamman v_n   (absolute_damping off: gamman 1/s)
//   model hertz/stiffness: F = k_n sqrt(R d) d - gamman sqrt(R d) m* v_n
//                          (k_n Pa, gamman 1/(m s))
//   model hertz:           F = 4/3 Y* sqrt(R d) d - 2 sqrt(5/6) beta sqrt(2 Y* sqrt(R d) m*) v_n,
//                          beta = ln e / sqrt(ln^2 e + pi^2), Y* from youngsModulus and
//                          poissonsRatio of both types: Tsuji's form (Tsuji et al., Powder
//                          Technol. 71 (1992) 239) with alpha = sqrt(5)(-beta). This beta(e) is the
//                          linear spring-dashpot's; for the Hertz spring it is approximate (Antypov
//                          & Elliott, EPL 94 (2011) 50004), hence the compensation in mapping.cpp
//                          (docs/physics.md §10.2).
// Against a wall (fix wall/gran ... primitive) R* = R and m* = m. `units si` needs
// `hard_particles yes` for Young's moduli above 1 GPa. Type 1: the ball(s); type 2: the walls.
#include <cmath>
#include <sstream>

#include "bouncecal/core/format.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {
namespace {

std::string Pair4(double v) {
  const std::string s = FormatShortest(v);
  return s + " " + s + " " + s + " " + s;
}

// The model name, its property lines and the pair/wall model text.
struct LiggghtsModel {
  std::string properties;
  std::string model;  // "model hertz tangential no_history"
};

LiggghtsModel ModelOf(const DeckInput& in) {
  const Mapping& m = in.mapping;
  const auto& c = m.coefficients;
  std::ostringstream p;
  LiggghtsModel out;
  if (m.form == NativeForm::kLinear) {
    // gamman (1/s) is multiplied by m* = m against the wall: c = m gamman.
    p << "fix k_n all property/global kn peratomtypepair 2 " << Pair4(c.at("k_n_n_m")) << "\n"
      << "fix k_t all property/global kt peratomtypepair 2 " << Pair4(0.0) << "\n"
      << "fix gamma_n all property/global gamman peratomtypepair 2 "
      << Pair4(c.at("gamman_abs_n_s_m") / in.mass_kg) << "\n"
      << "fix gamma_t all property/global gammat peratomtypepair 2 " << Pair4(0.0) << "\n";
    out.model = "model hooke/stiffness tangential no_history";
  } else if (m.form == NativeForm::kHertzViscoelastic) {
    p << "fix k_n all property/global kn peratomtypepair 2 " << Pair4(c.at("k_n_pa")) << "\n"
      << "fix k_t all property/global kt peratomtypepair 2 " << Pair4(0.0) << "\n"
      << "fix gamma_n all property/global gamman peratomtypepair 2 " << Pair4(c.at("gamman_1_m_s"))
      << "\n"
      << "fix gamma_t all property/global gammat peratomtypepair 2 " << Pair4(0.0) << "\n";
    out.model = "model hertz/stiffness tangential no_history";
  } else {
    // Both types carry the same Y and nu: Y* = Y / (2 (1 - nu^2)) gives the fitted k.
    const double nu = in.poisson_ratio;
    const double y = 2.0 * (1.0 - nu * nu) * c.at("Yeff_pa");
    p << "fix m_youngs all property/global youngsModulus peratomtype " << FormatShortest(y) << " "
      << FormatShortest(y) << "\n"
      << "fix m_poisson all property/global poissonsRatio peratomtype " << FormatShortest(nu) << " "
      << FormatShortest(nu) << "\n"
      << "fix m_restitution all property/global coefficientRestitution peratomtypepair 2 "
      << Pair4(c.at("coefficientRestitution")) << "\n";
    out.model = "model hertz tangential no_history";
  }
  p << "fix m_friction all property/global coefficientFriction peratomtypepair 2 " << Pair4(0.0)
    << "\n";
  out.properties = p.str();
  return out;
}

}  // namespace

std::string LiggghtsBounceDeck(const DeckInput& in) {
  const double r = in.radius_m, z0 = r + in.release_height_m;
  const LiggghtsModel model = ModelOf(in);
  std::ostringstream os;
  os << CommentBlock(in.comments, "# ");
  os << "# Run: liggghts -in in.bounce   (-var steps N to shorten; run.sh does this and writes\n"
     << "# impacts.csv)\n\n"
     << "atom_style granular\n"
     << "atom_modify map array\n"
     << "boundary f f f\n"
     << "newton off\n"
     << "communicate single vel yes\n"
     << "units si\n"
     << "hard_particles yes\n"
     << "region box block " << FormatShortest(-4 * r) << " " << FormatShortest(4 * r) << " "
     << FormatShortest(-4 * r) << " " << FormatShortest(4 * r) << " " << FormatShortest(-r) << " "
     << FormatShortest(z0 + 4 * r) << " units box\n"
     << "create_box 2 box\n"
     << "neighbor " << FormatShortest(0.1 * r) << " bin\n"
     << "neigh_modify delay 0\n"
     << model.properties << "pair_style gran " << model.model << "\n"
     << "pair_coeff * *\n"
     << "timestep " << FormatShortest(in.time_step_s) << "\n"
     << "fix gravity all gravity " << FormatShortest(in.g_m_s2) << " vector 0.0 0.0 -1.0\n"
     << "fix wall all wall/gran " << model.model << " primitive type 2 zplane 0.0\n"
     << "create_atoms 1 single 0 0 " << FormatShortest(z0) << " units box\n"
     << "set atom 1 diameter " << FormatShortest(2 * r) << " density "
     << FormatShortest(in.density_kg_m3) << "\n"
     << "fix integrate all nve/sphere\n"
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

std::string LiggghtsPackingDeck(const DeckInput& in) {
  // docs/physics.md §1: k_n = k_s = 1e7 N/m, mu = 0.3; hooke/stiffness damps with m* gamman, so the
  // same e needs gamman = 2 zeta sqrt(kn/m*): m* = m/2 between spheres (types 1-1), m against
  // the walls (types 1-2).
  const PackingScene ps(in.packing_restitution);
  const double kn = ps.kn, mu = ps.mu, d = ps.d, rho = ps.rho, gn_pp = ps.gn_pp, gn_pw = ps.gn_pw;
  auto pair = [](double pp, double pw) {
    return FormatShortest(pp) + " " + FormatShortest(pw) + " " + FormatShortest(pw) + " " +
           FormatShortest(pw);
  };
  std::ostringstream os;
  os << CommentBlock(in.comments, "# ");
  os << "# Run: mpirun -np N liggghts -in in.packing   (-var steps N, -var seed S)\n\n"
     << "atom_style granular\n"
     << "atom_modify map array\n"
     << "boundary f f f\n"
     << "newton off\n"
     << "communicate single vel yes\n"
     << "units si\n"
     << "# The pile settles at the bottom: split the ranks across x and y, never along z.\n"
     << "processors * * 1\n"
     << "region box block -0.105 0.105 -0.105 0.105 -0.001 0.25 units box\n"
     << "create_box 2 box\n"
     << "neighbor 0.002 bin\n"
     << "neigh_modify delay 0\n"
     << "fix k_n all property/global kn peratomtypepair 2 " << pair(kn, kn) << "\n"
     << "fix k_t all property/global kt peratomtypepair 2 " << pair(kn, kn) << "\n"
     << "fix gamma_n all property/global gamman peratomtypepair 2 " << pair(gn_pp, gn_pw) << "\n"
     << "fix gamma_t all property/global gammat peratomtypepair 2 "
     << pair(0.5 * gn_pp, 0.5 * gn_pw) << "\n"
     << "fix m_friction all property/global coefficientFriction peratomtypepair 2 " << pair(mu, mu)
     << "\n"
     << "pair_style gran model hooke/stiffness tangential history\n"
     << "pair_coeff * *\n"
     << "timestep " << FormatShortest(in.time_step_s) << "\n"
     << "fix gravity all gravity " << FormatShortest(in.g_m_s2) << " vector 0.0 0.0 -1.0\n"
     << "fix floor all wall/gran model hooke/stiffness tangential history primitive type 2 "
        "zplane 0.0\n"
     << "fix side all wall/gran model hooke/stiffness tangential history primitive type 2 "
        "zcylinder 0.1 0.0 0.0\n"
     << "variable seed index 86028121\n"  // LIGGGHTS seeds must be primes > 10000
     << "fix pts all particletemplate/sphere 15485863 atom_type 1 density constant "
     << FormatShortest(rho) << " radius constant " << FormatShortest(0.5 * d) << "\n"
     << "fix pdd all particledistribution/discrete 32452843 1 pts 1.0\n"
     << "# The hopper: spheres placed at random (no overlap) between 5 and 20 cm, at rest.\n"
     << "region hopper cylinder z 0 0 0.094 0.05 0.2 units box\n"
     << "fix ins all insert/pack seed ${seed} distributiontemplate pdd maxattempt 200 "
        "insert_every once overlapcheck yes all_in yes particles_in_region "
     << in.options.packing_particles << " region hopper\n"
     << "fix integrate all nve/sphere\n"
     << "variable steps index " << in.steps << "\n"
     << "compute rke all erotate/sphere\n"
     << "thermo_style custom step atoms ke c_rke\n"
     << "thermo " << std::max<long>(in.steps / 20, 1) << "\n"
     << "run ${steps}\n"
     << "write_dump all custom packing.dump id x y z radius\n";
  return os.str();
}

}  // namespace bouncecal::exporter

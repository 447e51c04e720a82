// LAMMPS deck of seed 003's column (column.hpp) for the Debian 12 build ("29 Sep 2021 -
// Update 2"), and the sphere file both simulators read.
//
// Keywords (LAMMPS GRANULAR package: pair_style granular, fix wall/gran granular, fix freeze,
// fix halt, delete_atoms):
//   pair_coeff I J hertz kn e damping tsuji tangential mindlin kt x mu rolling sds k_roll 0 mu_r
//     F_n = kn sqrt(R* d) d + alpha(e) sqrt(m* kn sqrt(R* d)) v_n (alpha: LAMMPS' polynomial),
//     F_t = min(mu F_n, |kt a xi + x eta_n v_t|), torque_roll = R* min(mu_r F_n, k_roll |xi_r|)
//   fix freeze on the floor spheres: zero force, and m* = the bead's mass against them.
// The beads settle behind the gate (fix halt at rest), are trimmed at the column height, the
// gate's wall fix is removed and the collapse runs to rest, dumping every 10 ms.
#include <cmath>
#include <cstdio>
#include <sstream>

#include "bouncecal/core/user_text.hpp"
#include "export/column_deck.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {
namespace {

// "hertz kn e damping tsuji tangential mindlin kt x mu rolling sds k 0 mu_r" for one pair.
std::string Granular(const ColumnContact& c) {
  std::ostringstream os;
  os << "hertz " << FormatShortest(c.kn_pa) << " " << FormatShortest(c.e_input_lammps)
     << " damping tsuji tangential mindlin " << FormatShortest(c.kt_pa) << " "
     << FormatShortest(c.tangential_damping_ratio) << " " << FormatShortest(ColumnPaper::kFriction)
     << " rolling sds " << FormatShortest(c.rolling_k_lammps) << " 0 "
     << FormatShortest(c.rolling_mu_lammps);
  return os.str();
}

}  // namespace

std::string ColumnDataText(const ColumnPlan& p, const std::vector<ColumnSphere>& spheres) {
  std::ostringstream os;
  os << "bouncecal column (seed 003): " << p.poured_beads << " beads poured at random (loose), "
     << p.floor_spheres << " fixed floor spheres; atom-ID type diameter density x y z (SI)\n\n"
     << spheres.size() << " atoms\n2 atom types\n\n"
     << "0 " << FormatShortest(ColumnPaper::kBoxLength_m) << " xlo xhi\n"
     << "0 " << FormatShortest(ColumnPaper::kBoxWidth_m) << " ylo yhi\n"
     << "0 " << FormatShortest(p.box_top_m) << " zlo zhi\n\nAtoms # sphere\n\n";
  char line[160];
  for (size_t i = 0; i < spheres.size(); ++i) {
    const ColumnSphere& s = spheres[i];
    std::snprintf(line, sizeof line, "%zu %d %.9g %g %.9g %.9g %.9g\n", i + 1, s.type, s.diameter_m,
                  ColumnPaper::kDensity_kg_m3, s.x_m, s.y_m, s.z_m);
    os << line;
  }
  return os.str();
}

std::string LammpsColumnDeck(const ColumnPlan& p, const std::vector<std::string>& comments) {
  const double h_trim = ColumnPaper::kColumnHeight_m - 0.5 * p.d_mean_m;
  const long thermo_every = std::max<long>(1, p.dump_every * 5);
  std::ostringstream os;
  os << CommentBlock(comments, "# ");
  os << "# Run: mpirun -np N lmp -in in.column   (-var settle_steps N -var collapse_steps N to\n"
     << "# shorten; run.sh does this and writes profile.csv, front.csv, summary.json)\n\n"
     << "units si\n"
     << "atom_style sphere\n"
     << "boundary f f f\n"
     << "newton off\n"
     << "comm_modify vel yes\n"
     << "# The column runs out along x: split the ranks along x only, rebalanced as it spreads.\n"
     << "processors * 1 1\n"
     << "read_data column.data\n"
     << "group beads type 1\n"
     << "group floor type 2\n"
     << "neighbor " << FormatShortest(0.1 * p.d_mean_m) << " bin\n"
     << "neigh_modify delay 0 every 1 check yes exclude type 2 2\n"
     << "pair_style granular\n"
     << "# bead-bead: e = " << FormatShortest(p.bead_bead.restitution) << " (alpha "
     << FormatShortest(p.bead_bead.alpha)
     << "); bead-floor and walls: e = " << FormatShortest(p.bead_wall.restitution) << " (alpha "
     << FormatShortest(p.bead_wall.alpha) << ")\n"
     << "pair_coeff 1 1 " << Granular(p.bead_bead) << "\n"
     << "pair_coeff 1 2 " << Granular(p.bead_floor) << "\n"
     << "pair_coeff 2 2 " << Granular(p.bead_floor) << "\n"

     << "fix freeze floor freeze\n"
     << "fix integrate beads nve/sphere\n"
     << "fix gravity beads gravity 9.8 vector 0 0 -1\n"
     << "variable wall string \"granular " << Granular(p.bead_wall) << "\"\n"
     << "fix wall_x0 beads wall/gran ${wall} xplane 0.0 NULL\n"
     << "fix wall_x1 beads wall/gran ${wall} xplane NULL "
     << FormatShortest(ColumnPaper::kBoxLength_m) << "\n"
     << "fix wall_y beads wall/gran ${wall} yplane 0.0 " << FormatShortest(ColumnPaper::kBoxWidth_m)
     << "\n"
     << "fix wall_z beads wall/gran ${wall} zplane 0.0 NULL\n"
     << "fix gate beads wall/gran ${wall} xplane NULL "
     << FormatShortest(ColumnPaper::kColumnLength_m) << "\n"
     << "timestep " << FormatShortest(p.time_step_s) << "\n"
     << "variable settle_steps index " << p.settle_steps << "\n"
     << "variable collapse_steps index " << p.collapse_steps << "\n"
     << "variable t equal step*dt\n"
     << "variable vrms equal sqrt(2*ke/mass(beads))\n"
     << "compute rke beads erotate/sphere\n"
     << "thermo_style custom step atoms v_t ke c_rke v_vrms\n"
     << "thermo " << thermo_every << "\n"
     << "# 1. settle behind the gate: at rest when the rms bead speed is below "
     << FormatShortest(p.rest_speed_m_s) << " m/s, after the pour's free fall ("
     << FormatShortest(p.settle_min_s) << " s)\n"
     << "variable settled equal \"(v_t > " << FormatShortest(p.settle_min_s) << ") && (v_vrms < "
     << FormatShortest(p.rest_speed_m_s) << ")\"\n"
     << "fix settle all halt 100 v_settled == 1 error continue\n"
     << "run ${settle_steps}\n"
     << "unfix settle\n"
     << "print \"column: settled after $(step) steps, top $(bound(beads,zmax)) m\"\n"
     << "# 2. trim at the column height (bead centres above H - d_mean/2)\n"
     << "region above block INF INF INF INF " << FormatShortest(h_trim) << " INF units box\n"
     << "delete_atoms region above\n"
     << "print \"column: beads $(count(beads)) floor $(count(floor)) box $(xlo) $(xhi) $(ylo) "
        "$(yhi) $(zlo) $(zhi)\"\n"
     << "# 3. the gate is removed at once and the column collapses\n"
     << "unfix gate\n"
     << "reset_timestep 0\n"
     << "fix balance all balance " << thermo_every << " 1.1 shift x 10 1.05\n"
     << "dump front beads custom " << p.dump_every << " column.dump id x y z radius\n"
     << "variable rest equal \"(v_t > " << FormatShortest(ColumnPaper::kFrameInterval_s)
     << ") && (v_vrms < " << FormatShortest(p.rest_speed_m_s) << ")\"\n"
     << "fix rest all halt 100 v_rest == 1 error continue\n"
     << "run ${collapse_steps}\n"
     << "undump front\n"
     << "write_dump beads custom rest.dump id x y z radius\n"
     << "print \"column: collapse ended after $(step) steps, t = $(v_t) s, at rest $(v_rest)\"\n";
  return os.str();
}

}  // namespace bouncecal::exporter

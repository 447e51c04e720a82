// The column scene (seed 003) without the simulators: q_phi, the bead sizes and counts, the pour,
// the damping carried from a fit to every pair, the LAMMPS coefficients that reproduce Yade's
// Hertz-Mindlin forces, the time step, column.awk on a known deposit, the CLI and every refusal.
// (The simulators run it in column_integration_test, label "integration".)
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/export/column.hpp"
#include "bouncecal/export/mapping.hpp"
#include "bouncecal/export/native_law.hpp"
#include "export/column_deck.hpp"
#include "fit_file.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

using nlohmann::json;
using testing_util::CommandResult;
using testing_util::RunCommand;
using testing_util::ScratchDir;
using testing_util::Slurp;
using testing_util::WriteFit;

const std::string kBin = BOUNCECAL_BINARY;

// A hertz-tsuji fit with restitution e, mapped onto a target (as export does).
ColumnFit TsujiFit(double e, ExportTarget target) {
  Scene s;
  s.law = {"hertz-tsuji", {{"e", e}}, ""};
  const std::vector<double> speeds = {0.3, 1.0, 2.0};
  const Mapping m = MapLaw(s, speeds, target);
  return exporter::MakeColumnFit("fit.json", m, BodyFromScene(s), {e, e, e});
}

ColumnPlan Plan(double scale, ExportTarget target, double e_bead = 0.8, double e_wall = 0.6) {
  ColumnOptions o;
  o.scale = scale;
  return PlanColumn(o, target, TsujiFit(e_bead, target), TsujiFit(e_wall, target));
}

double EffectiveModulus(double e1, double nu1, double e2, double nu2) {
  return 1.0 / ((1.0 - nu1 * nu1) / e1 + (1.0 - nu2 * nu2) / e2);
}

TEST(Column, QPhiOfTheReposeAngleIsThePapers) {
  // seed 003: "phi = 21 deg gives q_phi ~ 0.452"; q_phi grows with phi and ends at 26.57 deg.
  EXPECT_NEAR(QPhiFromFrictionAngle(21.0 * M_PI / 180.0), 0.452, 5e-4);
  EXPECT_LT(QPhiFromFrictionAngle(18.0 * M_PI / 180.0), QPhiFromFrictionAngle(22.0 * M_PI / 180.0));
  EXPECT_TRUE(std::isnan(QPhiFromFrictionAngle(27.0 * M_PI / 180.0)));
  EXPECT_NEAR(Plan(0.3, ExportTarget::kLammps).q_phi, 0.452, 5e-4);
}

TEST(Column, FullScaleFillsThePapersColumnWithAtLeast25000Beads) {
  const ColumnPlan p = Plan(1.0, ExportTarget::kLammps);
  EXPECT_EQ(p.expected_beads, ColumnPaper::kBeads);
  EXPECT_GE(p.poured_beads, 25000);  // the deck starts with at least the paper's count
  EXPECT_NEAR(p.d_mean_m, 5.4e-3, 1e-12);
  EXPECT_GT(p.pour_top_m, ColumnPaper::kColumnHeight_m);  // overtops: trimmed to 180 mm
  // Coarser beads: ~ scale^3 as many, diameters / scale, same box and column.
  const ColumnPlan q = Plan(0.5, ExportTarget::kLammps);
  EXPECT_NEAR(q.d_mean_m, 10.8e-3, 1e-12);
  EXPECT_NEAR(static_cast<double>(q.poured_beads) / p.poured_beads, 0.125, 0.02);
  ColumnOptions o;
  o.particles = 3146;  // = 25167 / 8
  const ColumnPlan r = PlanColumn(o, ExportTarget::kLammps, TsujiFit(0.8, ExportTarget::kLammps),
                                  TsujiFit(0.8, ExportTarget::kLammps));
  EXPECT_NEAR(r.scale, 0.5, 1e-4);
}

TEST(Column, SpheresStartApartInsideTheColumnWithThePapersSizes) {
  const ColumnPlan p = Plan(0.333, ExportTarget::kLammps);
  const std::vector<ColumnSphere> s = ColumnSpheres(p);
  std::vector<ColumnSphere> beads, floor;
  for (const ColumnSphere& c : s) (c.type == 1 ? beads : floor).push_back(c);
  ASSERT_EQ(static_cast<int>(beads.size()), p.poured_beads);
  ASSERT_EQ(static_cast<int>(floor.size()), p.floor_spheres);
  double sum = 0.0;
  for (size_t i = 0; i < beads.size(); ++i) {
    const ColumnSphere& a = beads[i];
    const double r = 0.5 * a.diameter_m;
    EXPECT_GE(a.diameter_m, p.d_min_m);
    EXPECT_LE(a.diameter_m, p.d_max_m);
    EXPECT_GT(a.x_m - r, 0.0);
    EXPECT_LT(a.x_m + r, ColumnPaper::kColumnLength_m);  // behind the gate
    EXPECT_GT(a.y_m - r, 0.0);
    EXPECT_LT(a.y_m + r, ColumnPaper::kBoxWidth_m);
    EXPECT_GT(a.z_m - r, p.floor_diameter_m);  // above the floor spheres
    sum += a.diameter_m;
    for (size_t j = i + 1; j < beads.size(); ++j) {
      const ColumnSphere& b = beads[j];
      const double gap = std::hypot(a.x_m - b.x_m, a.y_m - b.y_m, a.z_m - b.z_m) -
                         0.5 * (a.diameter_m + b.diameter_m);
      ASSERT_GT(gap, 0.0) << i << " " << j;
    }
  }
  EXPECT_NEAR(sum / static_cast<double>(beads.size()), p.d_mean_m, 0.02 * p.d_mean_m);
  // The floor spheres cover the box's floor without touching each other.
  EXPECT_GT(floor[1].y_m - floor[0].y_m, p.floor_diameter_m);
  EXPECT_NEAR(static_cast<double>(floor.size()) * p.floor_diameter_m * p.floor_diameter_m,
              ColumnPaper::kBoxLength_m * ColumnPaper::kBoxWidth_m, 0.05 * 0.08);
  // Seeded: the same seed gives the same beads, another seed others.
  EXPECT_EQ(ColumnSpheres(p)[7].diameter_m, s[7].diameter_m);
  ColumnPlan q = p;
  q.seed = 4;
  EXPECT_NE(ColumnSpheres(q)[7].diameter_m, s[7].diameter_m);
}

TEST(Column, FittedDampingReachesEveryPairWhateverItsSizeAndMass) {
  for (ExportTarget t : {ExportTarget::kLammps, ExportTarget::kYade}) {
    const ColumnPlan p = Plan(0.333, t, 0.8, 0.6);
    const bool clip = t == ExportTarget::kYade;
    EXPECT_NEAR(p.bead_bead.restitution, 0.8, 1e-9);
    EXPECT_NEAR(p.bead_wall.restitution, 0.6, 1e-9);
    EXPECT_NEAR(p.bead_floor.restitution, 0.6, 1e-9);  // the floor takes the wall's fit
    EXPECT_LT(p.bead_bead.e_error, 1e-6);
    // Tsuji's alpha fixes e for any m*, R*, stiffness: the column's pairs bounce at the fit's e.
    for (const ColumnContact& c : {p.bead_bead, p.bead_floor, p.bead_wall}) {
      const NativeModel m(NativeForm::kHertzTsuji, clip, c.kn_pa * std::sqrt(c.reduced_radius_m),
                          c.alpha);
      const ContactBody body = ContactBody::BallOnRigidWall(c.reduced_mass_kg, c.reduced_radius_m);
      EXPECT_NEAR(m.RestitutionAt(body, 0.05), c.restitution, 1e-6) << c.name;
      EXPECT_NEAR(m.RestitutionAt(body, 1.9), c.restitution, 1e-6) << c.name;
      EXPECT_NEAR(LammpsTsujiPolynomial(c.e_input_lammps), c.alpha, 1e-12) << c.name;
      EXPECT_NEAR(c.yade_betan * std::sqrt(6.0), c.alpha, 1e-15) << c.name;
    }
  }
  // Yade clips the attractive end: the same e needs more damping there.
  EXPECT_GT(Plan(0.333, ExportTarget::kYade).bead_bead.alpha,
            Plan(0.333, ExportTarget::kLammps).bead_bead.alpha + 0.005);
  // A given restitution replaces the fits' for every pair.
  ColumnOptions o;
  o.scale = 0.333;
  o.restitution = 0.3;
  const ColumnPlan g = PlanColumn(o, ExportTarget::kLammps, TsujiFit(0.8, ExportTarget::kLammps),
                                  TsujiFit(0.6, ExportTarget::kLammps));
  EXPECT_EQ(g.bead_bead.restitution, 0.3);
  EXPECT_EQ(g.bead_wall.restitution, 0.3);
  EXPECT_EQ(g.bead_bead.e_error, 0.0);
}

TEST(Column, LammpsCoefficientsReproduceYadesHertzMindlinForces) {
  const ColumnPlan p = Plan(0.333, ExportTarget::kLammps);
  const double e = ColumnPaper::kYoungs_pa, nu = p.poisson_ratio;
  // Normal: kn = 4/3 E*, E* of two beads and of bead and plastic wall (Johnson eq. 4.22).
  EXPECT_NEAR(p.bead_bead.kn_pa, 4.0 / 3.0 * e / (2.0 * (1.0 - nu * nu)), 1.0);
  EXPECT_NEAR(p.bead_wall.kn_pa, 4.0 / 3.0 * EffectiveModulus(e, nu, 3e9, 0.35), 1.0);
  // Yade's wall is stiffened so that its E* on R/2 gives LAMMPS' Kno on R.
  EXPECT_NEAR(EffectiveModulus(e, nu, p.yade_wall_youngs_pa, p.wall_poisson),
              std::sqrt(2.0) * EffectiveModulus(e, nu, 3e9, 0.35), 1.0);
  // Tangential: Mindlin's 4G/(2 - nu) for equal materials, and Yade's damping ratio
  // sqrt(ks / kn_tangent) = sqrt(2 (1 - nu)/(2 - nu)).
  EXPECT_NEAR(p.bead_bead.kt_pa, 4.0 * e / (2.0 * (1.0 + nu)) / (2.0 - nu), 1.0);
  EXPECT_NEAR(p.bead_bead.tangential_damping_ratio, std::sqrt(2.0 * (1.0 - nu) / (2.0 - nu)),
              1e-12);
  // Rolling: LAMMPS' limit torque mu_roll R* F_n equals Yade's eta R_mean F_n for every class.
  const double r = 0.5 * p.d_mean_m, rf = 0.5 * p.floor_diameter_m;
  EXPECT_NEAR(p.bead_bead.rolling_mu_lammps * 0.5 * r, p.rolling_friction * r, 1e-15);
  EXPECT_NEAR(p.bead_floor.rolling_mu_lammps * r * rf / (r + rf),
              p.rolling_friction * 0.5 * (r + rf), 1e-15);
  EXPECT_NEAR(p.bead_wall.rolling_mu_lammps * r, p.rolling_friction * r, 1e-15);
  // and its torque stiffness k_roll R*^2 is the one k_r Yade takes for every contact.
  EXPECT_NEAR(p.bead_bead.rolling_k_lammps * 0.25 * r * r, p.rolling_stiffness_nm_rad,
              1e-9 * p.rolling_stiffness_nm_rad);
  EXPECT_NEAR(p.bead_wall.rolling_k_lammps * r * r, p.rolling_stiffness_nm_rad,
              1e-9 * p.rolling_stiffness_nm_rad);
}

TEST(Column, TimeStepResolvesTheShortestContactWithinItsBudget) {
  const ColumnPlan p = Plan(0.333, ExportTarget::kLammps);
  const double tc = std::min(
      {p.bead_bead.contact_time_s, p.bead_floor.contact_time_s, p.bead_wall.contact_time_s});
  EXPECT_LE(p.time_step_s, tc / 10.0 * (1.0 + 1e-12));
  EXPECT_LE(p.time_step_e_error, 0.01);
  // Coarser beads, longer contacts (t_c ~ R for Hertz at a fixed speed and material).
  EXPECT_NEAR(
      Plan(0.5, ExportTarget::kLammps).bead_bead.contact_time_s / p.bead_bead.contact_time_s,
      0.333 / 0.5, 0.01);
  EXPECT_GE(static_cast<double>(p.settle_steps) * p.time_step_s, p.settle_max_s);
  EXPECT_GE(static_cast<double>(p.collapse_steps) * p.time_step_s, p.max_collapse_s);
  EXPECT_NEAR(p.dump_interval_s, 0.01, 0.5 * p.time_step_s);
  // At rest: a tenth of a mean diameter per 25 fps frame.
  EXPECT_NEAR(p.rest_speed_m_s, 0.1 * p.d_mean_m / 0.04, 1e-15);
}

TEST(Column, RefusesBeadsThatDoNotFitTheColumnOrTheMemory) {
  try {
    Plan(0.15, ExportTarget::kLammps);
    ADD_FAILURE() << "scale 0.15 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    EXPECT_NE(std::string(e.what()).find("at least 3 must fit"), std::string::npos) << e.what();
  }
  try {
    Plan(40.0, ExportTarget::kYade);  // 1.6e9 beads
    ADD_FAILURE() << "scale 40 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    EXPECT_NE(std::string(e.what()).find("more than this machine's"), std::string::npos)
        << e.what();
  }
  std::string why;
  ColumnOptions o;
  o.scale = 0.0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("scale"), std::string::npos);
}

// ---- column.awk on a known deposit --------------------------------------------------------

void WriteDump(std::ofstream& f, long step, const std::vector<std::array<double, 4>>& beads) {
  f << "ITEM: TIMESTEP\n"
    << step << "\nITEM: NUMBER OF ATOMS\n"
    << beads.size()
    << "\nITEM: BOX BOUNDS ff ff ff\n0 0.4\n0 0.2\n0 0.3\nITEM: ATOMS id x y z radius\n";
  int id = 1;
  for (const auto& b : beads) f << id++ << " " << b[0] << " 0.1 " << b[1] << " " << b[2] << "\n";
}

TEST(ColumnAwk, MeasuresFrontHeightAndProfilesOfTheContiguousDeposit) {
  ScratchDir dir;
  std::ofstream(dir / "column.awk") << exporter::ColumnAwk();
  std::ofstream(dir / "log") << "Loop time of 10 on 2 procs for 1000 steps with 50 atoms\n"
                             << "column: beads 3 floor 7 box 0 0.4 0 0.2 0 0.3\n"
                             << "Loop time of 20 on 2 procs for 4000 steps with 50 atoms\n"
                             << "column: collapse ended after 4000 steps, t = 0.4 s, at rest 1\n";
  {
    // dt = 1e-4 s: snapshots at 0, 0.04 s (step 400); w = 0.01 m bins.
    std::ofstream d(dir / "column.dump");
    WriteDump(d, 0, {{0.005, 0.175, 0.005}, {0.015, 0.1, 0.005}, {0.025, 0.05, 0.005}});
    // at 0.04 s the bead at 0.035 m is beyond an empty bin
    WriteDump(d, 400, {{0.005, 0.12, 0.005}, {0.015, 0.1, 0.005}, {0.035, 0.02, 0.005}});
    std::ofstream r(dir / "rest.dump");
    // a bead at 0.3 m beyond an empty bin is not part of the deposit
    WriteDump(r, 4000, {{0.005, 0.06, 0.005}, {0.015, 0.04, 0.005}, {0.3, 0.005, 0.005}});
  }
  const CommandResult c = RunCommand(
      "sh",
      "-c 'cd " + dir.path().string() +
          " && awk -v dt=1e-4 -v every=0.01 -v w=0.01 -v width=0.01 -v h_col=0.18 -v frame=0.04 "
          "-v frames=13 -v li=0.1 "
          "-v ranks=2 -v wall=31 -f column.awk log column.dump rest.dump'");
  ASSERT_EQ(c.exit_code, 0) << c.err;
  const json s = json::parse("{" + c.out + "\"end\": 0}");
  EXPECT_EQ(s["beads"], 3);
  EXPECT_EQ(s["floor_spheres"], 7);
  EXPECT_NEAR(s["initial_height_m"].get<double>(), 0.18, 1e-9);  // t = 0: one bin column
  EXPECT_NEAR(s["run_out_m"].get<double>(), 0.02, 1e-9);         // 0.015 + r; 0.3 excluded
  EXPECT_NEAR(s["final_height_m"].get<double>(), 0.065, 1e-9);
  EXPECT_EQ(s["at_rest"], true);
  EXPECT_NEAR(s["time_to_rest_s"].get<double>(), 0.4, 1e-9);
  EXPECT_EQ(s["steps"], 5000);
  EXPECT_NEAR(s["particle_steps_per_s_per_rank"].get<double>(), 3.0 * 4000 / 20 / 2, 1e-9);
  // At 0.04 s: bead 1 above the diagonal z = 0.18 (1 - x / 0.1) fell (0.175 -> 0.12 m); of the
  // two below it, bead 2 stayed and bead 3 moved 0.01 m.
  EXPECT_EQ(s["moved_by_first_frame"]["above_diagonal"].get<double>(), 1.0);
  EXPECT_EQ(s["moved_by_first_frame"]["below_diagonal"].get<double>(), 0.5);
  const std::string front = Slurp(dir / "front.csv.tmp");
  EXPECT_EQ(front, "time_s,front_m,height_m\n0,0.03,0.18\n0.04,0.02,0.125\n");
  const std::string profile = Slurp(dir / "profile.csv.tmp");
  EXPECT_NE(profile.find("0,0,0.005,0.18\n"), std::string::npos) << profile;
  EXPECT_NE(profile.find("0.04,0.04,0.015,0.105\n"), std::string::npos) << profile;
  EXPECT_EQ(profile.find("0.04,0.04,0.035"), std::string::npos) << profile;
  EXPECT_NE(profile.find("rest,0.4,0.015,0.045\n"), std::string::npos) << profile;
  EXPECT_EQ(profile.find("0.305"), std::string::npos) << profile;
}

// ---- the CLI --------------------------------------------------------------------------------

TEST(ColumnCli, WritesBothDecksWithTheMappedDampingAndQPhi) {
  ScratchDir dir;
  const std::string bead = WriteFit(dir, "hertz-tsuji", {{"e", 0.85}}, "bead.json");
  const std::string wall = WriteFit(dir, "walton-braun", {{"gamma", 0.3}}, "wall.json");
  CommandResult r =
      RunCommand(kBin, "export " + bead + " --wall-params " + wall +
                           " --to lammps --scene column --scale 0.3 -o " + (dir / "l") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json m = json::parse(r.out);
  EXPECT_EQ(m["scene"], "column");
  EXPECT_NEAR(m["column"]["q_phi"].get<double>(), 0.452, 5e-4);
  EXPECT_NEAR(m["column"]["bead_bead"]["restitution"].get<double>(), 0.85, 2e-3);
  EXPECT_NEAR(m["column"]["bead_wall"]["restitution"].get<double>(), std::sqrt(0.7 / 1.3), 2e-3);
  for (const char* f :
       {"in.column", "column.data", "run.sh", "column.awk", "column.json", "mapping.json"}) {
    EXPECT_TRUE(std::filesystem::exists((dir / "l") + "/" + f)) << f;
  }
  const std::string deck = Slurp(dir / "l/in.column");
  EXPECT_NE(deck.find("pair_coeff 1 1 hertz"), std::string::npos);
  EXPECT_NE(deck.find("q_phi = 0.45"), std::string::npos);
  EXPECT_NE(deck.find("damping tsuji"), std::string::npos);
  EXPECT_NE(Slurp(dir / "l/run.sh").find("mpirun"), std::string::npos);
  // Yade: the same beads (the same file), its own damping under the clipped end.
  r = RunCommand(kBin, "export " + bead + " --wall-params " + wall +
                           " --to yade --scene column --scale 0.3 -o " + (dir / "y") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(Slurp(dir / "y/column.data"), Slurp(dir / "l/column.data"));
  const std::string py = Slurp(dir / "y/column.py");
  EXPECT_NE(py.find("MatchMaker"), std::string::npos);
  EXPECT_NE(py.find("includeMoment=True"), std::string::npos);
  EXPECT_NE(Slurp(dir / "y/run.sh").find("yade -j \"$NP\""), std::string::npos);
  // The human summary prints q_phi beside mu.
  r = RunCommand(kBin,
                 "export " + bead + " --to lammps --scene column --scale 0.3 -o " + (dir / "h"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("mu = 0.38, q_phi = 0.452"), std::string::npos) << r.out;
}

TEST(ColumnCli, RefusesBeforeWritingAnything) {
  ScratchDir dir;
  const std::string bead = WriteFit(dir, "hertz-tsuji", {{"e", 0.85}}, "bead.json");
  // beads too large for the column; more memory than the machine has; LIGGGHTS
  for (const auto& [flags, code, text] : std::vector<std::tuple<std::string, int, std::string>>{
           {"--to lammps --scale 0.1", 9, "at least 3 must fit"},
           {"--to lammps --particles 20", 9, "at least 3 must fit"},
           {"--to yade --scale 40", 9, "more than this machine's"},
           {"--to liggghts --scale 0.3", 2, "lammps and yade only"},
           {"--to lammps --scale 0", 2, "scale"}}) {
    const CommandResult r =
        RunCommand(kBin, "export " + bead + " --scene column " + flags + " -o " + (dir / "o"));
    EXPECT_EQ(r.exit_code, code) << flags << ": " << r.err;
    EXPECT_NE(r.err.find(text), std::string::npos) << flags << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir / "o")) << flags;
  }
  // A law whose native form is too far from the fit (viscoelastic Hertz in Yade) is refused with
  // the mapping's error, as the bounce deck refuses it, unless allowed.
  const std::string hv = WriteFit(dir, "hertz-viscoelastic", {{"A", 2e-6}}, "hv.json");
  CommandResult r =
      RunCommand(kBin, "export " + hv + " --to yade --scene column --scale 0.3 -o " + (dir / "o"));
  EXPECT_EQ(r.exit_code, 9);
  EXPECT_NE(r.err.find("cannot be carried to the column in yade within e error 0.01"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "o"));
  r = RunCommand(kBin, "export " + hv + " --to yade --scene column --scale 0.3 -o " + (dir / "o") +
                           " --allow-approximation --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GT(json::parse(r.out)["max_e_error"].get<double>(), 0.01);
  // The wall file is checked too.
  r = RunCommand(kBin, "export " + bead + " --wall-params " + (dir / "missing.json") +
                           " --to lammps --scene column --scale 0.3 -o " + (dir / "w"));
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "w"));
}

}  // namespace
}  // namespace bouncecal

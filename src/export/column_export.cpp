// `export --scene column` (export.hpp, column.hpp): the fits mapped as for the bounce deck, the
// column planned and refused before anything is written, then the directory.
#include <algorithm>
#include <filesystem>
#include <sstream>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/export/column.hpp"
#include "export/column_deck.hpp"
#include "export/deck.hpp"
#include "fit/text.hpp"

namespace bouncecal::exporter {
namespace {

namespace fs = std::filesystem;

nlohmann::json ContactJson(const ColumnContact& c) {
  return {{"restitution", c.restitution},
          {"e_error", c.e_error},
          {"alpha", c.alpha},
          {"lammps_e_input", c.e_input_lammps},
          {"yade_betan", c.yade_betan},
          {"kn_pa", c.kn_pa},
          {"kt_pa", c.kt_pa},
          {"tangential_damping_ratio", c.tangential_damping_ratio},
          {"lammps_rolling_mu", c.rolling_mu_lammps},
          {"lammps_rolling_k_n_m", c.rolling_k_lammps},
          {"contact_time_s", c.contact_time_s}};
}

nlohmann::json PlanJson(const ColumnPlan& p) {
  return {{"scale", p.scale},
          {"bead_diameter_m",
           {{"mean", p.d_mean_m}, {"sigma", p.d_sigma_m}, {"min", p.d_min_m}, {"max", p.d_max_m}}},
          {"floor_sphere_diameter_m", p.floor_diameter_m},
          {"box_m", {ColumnPaper::kBoxLength_m, ColumnPaper::kBoxWidth_m, p.box_top_m}},
          {"column_m", {ColumnPaper::kColumnLength_m, ColumnPaper::kBoxWidth_m, p.column_height_m}},
          {"poured_beads", p.poured_beads},
          {"expected_beads", p.expected_beads},
          {"floor_spheres", p.floor_spheres},
          {"density_kg_m3", ColumnPaper::kDensity_kg_m3},
          {"youngs_modulus_pa", ColumnPaper::kYoungs_pa},
          {"poisson_ratio", p.poisson_ratio},
          {"wall_youngs_modulus_pa", p.wall_youngs_pa},
          {"yade_wall_youngs_modulus_pa", p.yade_wall_youngs_pa},
          {"friction", p.friction},
          {"repose_angle_deg", ColumnPaper::kReposeAngle_deg},
          {"q_phi", p.q_phi},
          {"rolling_friction", p.rolling_friction},
          {"rolling_stiffness_n_m_rad", p.rolling_stiffness_nm_rad},
          {"rest_speed_m_s", p.rest_speed_m_s},
          {"settle_min_s", p.settle_min_s},
          {"settle_max_s", p.settle_max_s},
          {"max_collapse_s", p.max_collapse_s},
          {"dump_interval_s", p.dump_interval_s},
          {"time_step_s", p.time_step_s},
          {"time_step_e_error", p.time_step_e_error},
          {"memory_bytes", p.memory_bytes},
          {"bead_params", p.bead_fit.params_path},
          {"wall_params", p.wall_fit.params_path},
          {"bead_bead", ContactJson(p.bead_bead)},
          {"bead_floor", ContactJson(p.bead_floor)},
          {"bead_wall", ContactJson(p.bead_wall)},
          {"seed", p.seed}};
}

// A fit whose column e is further from the fitted e(v) than allowed is refused, as the bounce
// deck refuses its mapping.
void CheckError(const ColumnFit& f, const ExportOptions& o, const std::string& target) {
  if (o.column.restitution > 0.0 || f.e_error <= o.max_e_error || o.allow_approximation) return;
  throw Error(ErrorCode::kBadParameter,
              f.params_path + ": law " + f.mapping.law + " cannot be carried to the column in " +
                  target + " within e error " + FormatShortest(o.max_e_error) +
                  ": the native law (" + f.mapping.native_law + ") as a constant e = " +
                  FormatShortest(f.restitution) + " is off by " + FormatShortest(f.e_error) +
                  " over " + FormatShortest(f.mapping.speeds_m_s.front()) + " .. " +
                  FormatShortest(f.mapping.speeds_m_s.back()) +
                  " m/s; not exported (ExportOptions::allow_approximation accepts it)");
}

}  // namespace

std::vector<std::string> ColumnComments(const ColumnPlan& p) {
  std::vector<std::string> c;
  auto contact = [&c](const ColumnContact& k, const std::string& from) {
    c.push_back(k.name + ": e = " + FormatGeneral(k.restitution, 4) + " (" + from + ", e error " +
                FormatGeneral(k.e_error, 4) + "), Tsuji alpha = " + FormatGeneral(k.alpha, 4) +
                ", kn = " + FormatGeneral(k.kn_pa, 4) + " Pa, kt = " + FormatGeneral(k.kt_pa, 4) +
                " Pa, contact time " + FormatGeneral(k.contact_time_s, 4) + " s");
  };
  c.push_back(
      "seed 003 (Fei et al. 2016) granular column: box 0.4 x 0.2 m, gate at x = 0.1 m, "
      "column 0.1 x 0.2 x 0.18 m (a = 1.8)");
  c.push_back("beads: d normal " + FormatGeneral(p.d_mean_m, 4) + " +- " +
              FormatGeneral(p.d_sigma_m, 4) + " m within " + FormatGeneral(p.d_min_m, 4) + " .. " +
              FormatGeneral(p.d_max_m, 4) + " (the paper's 4.9-5.9 mm / scale " +
              FormatGeneral(p.scale, 4) + "), rho 2200 kg/m^3, E 5.5 GPa, nu " +
              FormatGeneral(p.poisson_ratio, 4) + " (assumed), " + std::to_string(p.poured_beads) +
              " poured, ~" + std::to_string(p.expected_beads) + " after the trim");
  c.push_back("friction mu = " + FormatGeneral(p.friction, 4) + " (repose angle 21 deg); q_phi = " +
              FormatGeneral(p.q_phi, 4) + " (seed 003 eq. 11, for MPM/TGT comparisons)");
  c.push_back(
      "rolling friction (seed 003 eq. 13, elastic-plastic): limit torque mu_r R_mean F_n, "
      "mu_r = " +
      FormatGeneral(p.rolling_friction, 4) +
      "; stiffness k_r = " + FormatGeneral(p.rolling_stiffness_nm_rad, 4) +
      " N m/rad (k_t R*^2 at the column's base load)");
  c.push_back("floor: " + std::to_string(p.floor_spheres) + " fixed spheres of " +
              FormatGeneral(p.floor_diameter_m, 4) +
              " m (the sandpaper); walls and gate: plastic, E " +
              FormatGeneral(p.wall_youngs_pa, 4) + " Pa, nu " + FormatGeneral(p.wall_poisson, 4));
  contact(p.bead_bead, p.bead_fit.params_path.empty() ? "given" : p.bead_fit.params_path);
  contact(p.bead_floor, p.wall_fit.params_path.empty() ? "given" : p.wall_fit.params_path);
  contact(p.bead_wall, p.wall_fit.params_path.empty() ? "given" : p.wall_fit.params_path);
  c.push_back("time step " + FormatGeneral(p.time_step_s, 4) + " s: " + p.time_step_choice);
  c.push_back("at rest: rms bead speed < " + FormatGeneral(p.rest_speed_m_s, 4) +
              " m/s (a tenth of a mean diameter per 25 fps frame); settle <= " +
              FormatGeneral(p.settle_max_s, 4) +
              " s, collapse <= " + FormatGeneral(p.max_collapse_s, 4) + " s");
  for (const std::string& n : p.notes) c.push_back("note: " + n);
  return c;
}

ExportResult ExportColumn(const std::string& params_path, const std::string& out_dir,
                          const ExportOptions& options) {
  const ExportTarget target = options.target;
  const ColumnOptions& co = options.column;
  // Stage 1: both fits, mapped onto the target as for the bounce deck; the directory checked.
  const MappedFile bead = MapParamFile(params_path, target, options.force);
  const std::string wall_path = co.wall_params.empty() ? params_path : co.wall_params;
  const MappedFile wall =
      co.wall_params.empty() ? MappedFile{} : MapParamFile(wall_path, target, options.force);
  CheckOutputDirectory(out_dir, options.force);
  const MappedFile& w = co.wall_params.empty() ? bead : wall;
  ColumnFit bead_fit = MakeColumnFit(params_path, bead.mapping, bead.body, bead.e_fit);
  ColumnFit wall_fit = MakeColumnFit(wall_path, w.mapping, w.body, w.e_fit);
  const std::string target_name = ExportTargetName(target);
  CheckError(bead_fit, options, target_name);
  CheckError(wall_fit, options, target_name);
  // Stage 2: the column (refuses sizes that do not fit the column or the memory).
  ColumnPlan plan = PlanColumn(co, target, bead_fit, wall_fit);

  ExportResult r;
  r.target = target_name;
  r.scene = ExportSceneName(ExportScene::kColumn);
  r.law = bead.replay.scene.law.name;
  r.law_json = ExportedLawJson(bead.pf, *bead.law, bead.replay.scene);
  AddVersionNotes(&r, target, options.simulator_version);
  for (const std::string& n : bead_fit.notes) r.notes.push_back("bead-bead: " + n);
  if (!co.wall_params.empty()) {
    for (const std::string& n : wall_fit.notes) r.notes.push_back("bead-wall: " + n);
  }
  if (co.restitution > 0.0) {
    r.notes.push_back("restitution " + FormatShortest(co.restitution) +
                      " given for every pair: the fits' damping is not used");
  }
  r.native_law =
      target == ExportTarget::kYade
          ? "Ip2_FrictMat_FrictMat_MindlinPhys(betan MatchMaker, krot, eta) + "
            "Law2_ScGeom_MindlinPhys_Mindlin(includeMoment)"
          : "pair_style granular hertz kn e damping tsuji tangential mindlin rolling sds";
  r.kind = bead.mapping.kind;
  r.exact = bead.mapping.exact && bead_fit.e_error == 0.0;
  r.max_e_error = std::max(plan.bead_bead.e_error, plan.bead_wall.e_error);
  r.max_contact_time_error = bead.mapping.max_contact_time_error;
  r.coefficients = bead.mapping.coefficients;
  r.speeds_m_s = bead.speeds;
  r.time_step_s = plan.time_step_s;
  r.time_step_e_error = plan.time_step_e_error;
  r.steps_per_contact = std::min({plan.bead_bead.contact_time_s, plan.bead_floor.contact_time_s,
                                  plan.bead_wall.contact_time_s}) /
                        plan.time_step_s;
  r.steps = plan.settle_steps + plan.collapse_steps;
  r.run_time_s = plan.settle_max_s + plan.max_collapse_s;
  r.trace_every = static_cast<int>(plan.dump_every);
  r.column = PlanJson(plan);
  r.column["q_phi_note"] = "q_phi = " + FormatGeneral(plan.q_phi, 4) +
                           " from the 21 deg friction angle "
                           "(seed 003 eq. 11), beside mu = " +
                           FormatShortest(plan.friction);

  // Stage 3: the files, each written atomically, only now.
  std::vector<std::string> comments = ColumnComments(plan);
  comments.insert(comments.begin(), "written for " + r.simulator_version);
  comments.insert(comments.begin(), "bouncecal export (" + r.target + ", column) of " +
                                        params_path +
                                        (co.wall_params.empty() ? "" : " and " + co.wall_params));
  for (const std::string& n : r.notes) comments.push_back("note: " + n);
  std::vector<std::pair<std::string, std::string>> files;
  files.push_back(target == ExportTarget::kYade
                      ? std::pair{std::string("column.py"), YadeColumnScript(plan, comments)}
                      : std::pair{std::string("in.column"), LammpsColumnDeck(plan, comments)});
  files.push_back({"column.data", ColumnDataText(plan, ColumnSpheres(plan))});
  files.push_back({"run.sh", ColumnRunScript(plan)});
  files.push_back({"column.awk", ColumnAwk()});
  files.push_back({"column.json", DumpJson(r.column, 2) + "\n"});
  PrepareOutputDirectory(out_dir, options.force);
  for (const auto& f : files) r.files.push_back(f.first);
  r.files.push_back("mapping.json");
  std::vector<std::string> inputs = {params_path};
  if (!co.wall_params.empty()) inputs.push_back(co.wall_params);
  const WriteOptions wo{.force = true, .inputs = inputs};
  for (const auto& [name, text] : files) {
    WriteFileAtomically((fs::path(out_dir) / name).string(), text, wo);
  }
  fs::permissions(fs::path(out_dir) / "run.sh",
                  fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                  fs::perm_options::add);
  WriteFileAtomically((fs::path(out_dir) / "mapping.json").string(),
                      DumpJson(ExportResultJson(r), 2) + "\n", wo);
  return r;
}

}  // namespace bouncecal::exporter

// `bouncecal export`: a parameter file -> a directory a DEM simulator runs as it is.
//
//   bouncecal export params.json --to lammps -o bounce_lammps
//   bouncecal export params.json --to yade -o bounce_yade --json
//   bouncecal export params.json --to lammps --scene packing -o packing
//   bouncecal export params.json --to yade --scene column --scale 0.333 -o column
//
// Human summary on stdout by default; --json prints the mapping ({target, simulator_version,
// law, native_law, exact, max_e_error, notes[], ...}, also written to DIR/mapping.json).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/export/export.hpp"
#include "commands.hpp"
#include "output.hpp"

namespace bouncecal::cli {
namespace {

struct ExportFlags {
  std::string params;
  std::string to;
  std::string scene = "bounce";
  std::string out_dir;
  bool json = false;
  bool force = false;
  bool allow_approximation = false;
  int impacts = 10;
  double dt_e_error = 5e-4;
  double packing_time_s = 3.0;
  int particles = 2000;
  double packing_restitution = 0.0;
  bool particles_given = false;
  double scale = 1.0;
  std::string wall_params;
  double column_restitution = 0.0;
  double rolling_friction = ColumnOptions{}.rolling_friction;
  uint64_t column_seed = ColumnOptions{}.seed;
};

void PrintHuman(const ExportResult& r, const std::string& dir) {
  std::printf("%s -> %s (%s), written for %s\n", r.law.c_str(), r.target.c_str(), r.scene.c_str(),
              r.simulator_version.c_str());
  std::printf("native law: %s  [%s]\n", r.native_law.c_str(), r.kind.c_str());
  std::printf("mapping e error: %.3g (max over %.4g .. %.4g m/s)%s\n", r.max_e_error,
              r.speeds_m_s.front(), r.speeds_m_s.back(), r.exact ? ", exact" : "");
  std::printf("time step: %.4g s (%.0f steps per contact), its e error %.2g; %ld steps, %.4g s\n",
              r.time_step_s, r.steps_per_contact, r.time_step_e_error, r.steps, r.run_time_s);
  if (r.column.is_object()) {
    const nlohmann::json& c = r.column;
    std::printf(
        "column: %d beads poured (~%d after the trim, scale %.4g), "
        "%d floor spheres; e bead-bead %.4g, bead-wall %.4g; mu = %.2f, q_phi = %.3f\n",
        c["poured_beads"].get<int>(), c["expected_beads"].get<int>(), c["scale"].get<double>(),
        c["floor_spheres"].get<int>(), c["bead_bead"]["restitution"].get<double>(),
        c["bead_wall"]["restitution"].get<double>(), c["friction"].get<double>(),
        c["q_phi"].get<double>());
  }
  for (const std::string& n : r.notes) std::printf("note: %s\n", n.c_str());
  std::printf("wrote %s/:", dir.c_str());
  for (const std::string& f : r.files) std::printf(" %s", f.c_str());
  std::printf("\nrun: %s/run.sh\n", dir.c_str());
}

void Run(const ExportFlags& f) {
  ExportOptions o;
  if (!ParseExportTarget(f.to, &o.target)) {
    throw Error(ErrorCode::kUsage, "--to " + f.to + ": expected lammps, liggghts or yade");
  }
  if (!ParseExportScene(f.scene, &o.scene)) {
    throw Error(ErrorCode::kUsage, "--scene " + f.scene + ": expected bounce, packing or column");
  }
  o.force = f.force;
  o.allow_approximation = f.allow_approximation;
  o.impacts = f.impacts;
  o.time_step_e_error = f.dt_e_error;
  o.packing_time_s = f.packing_time_s;
  if (o.scene == ExportScene::kPacking) o.packing_particles = f.particles;
  o.packing_restitution = f.packing_restitution;
  o.column.scale = f.scale;
  o.column.particles = f.particles_given && o.scene == ExportScene::kColumn ? f.particles : 0;
  o.column.wall_params = f.wall_params;
  o.column.restitution = f.column_restitution;
  o.column.rolling_friction = f.rolling_friction;
  o.column.seed = f.column_seed;
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  const ExportResult r = ExportDeck(f.params, f.out_dir, o);  // main() names the flags
  if (f.json) {
    std::cout << DumpJson(ExportResultJson(r), 2) << "\n";
  } else {
    PrintHuman(r, f.out_dir);
  }
}

}  // namespace

void RegisterExport(CLI::App& app) {
  auto flags = std::make_shared<ExportFlags>();
  CLI::App* sub = app.add_subcommand(
      "export", "write a directory a DEM simulator runs: LAMMPS, LIGGGHTS or Yade input, run.sh");
  sub->add_option("params", flags->params, "parameter file (calibrate -o)")->required();
  sub->add_option("--to", flags->to, "target simulator: lammps, liggghts or yade")->required();
  sub->add_option("--scene", flags->scene,
                  "bounce (the fit's drop, default), packing (seed 002's validation) or column "
                  "(seed 003's granular column collapse, docs/column.md)");
  AddOutputOption(sub, "-o,--output", &flags->out_dir, "output directory (must not exist)")
      ->required();
  sub->add_flag("--json", flags->json, "the mapping as JSON on stdout");
  sub->add_flag("--force", flags->force,
                "replace an existing directory's files; export a fit that did not converge");
  sub->add_flag("--allow-approximation", flags->allow_approximation,
                "export the closest native law even when its e error exceeds 0.01");
  sub->add_option("--impacts", flags->impacts, "bounce: impacts the run covers (default 10)");
  sub->add_option("--dt-e-error", flags->dt_e_error,
                  "bounce: largest e error the time step may cost (default 5e-4)");
  sub->add_option("--packing-time", flags->packing_time_s,
                  "packing: simulated time, s (default 3, the seed paper's)");
  CLI::Option* particles = sub->add_option(
      "--particles", flags->particles,
      "packing: spheres poured (default 2000); column: beads in the column (sets --scale)");
  sub->add_option("--packing-restitution", flags->packing_restitution,
                  "packing: pairwise e instead of the fit's (to see how damping matters)");
  sub->add_option("--scale", flags->scale,
                  "column: bead diameters divided by this (~25167 scale^3 beads; default 1, the "
                  "paper's)");
  sub->add_option("--wall-params", flags->wall_params,
                  "column: parameter file of the bead-wall contact (default: the bead-bead one)");
  sub->add_option("--column-restitution", flags->column_restitution,
                  "column: e for every pair instead of the fits' (to see how damping matters)");
  sub->add_option("--rolling-friction", flags->rolling_friction,
                  "column: rolling friction coefficient mu_r (default 0.093, docs/column.md)");
  sub->add_option("--column-seed", flags->column_seed,
                  "column: seed of the bead sizes and the pour (default 3)");
  sub->callback([flags, particles]() {
    flags->particles_given = particles->count() > 0;
    Run(*flags);
  });
}

}  // namespace bouncecal::cli

// bouncecal/export/export.hpp — parameter file -> a directory a DEM simulator runs as it is.
//
// ExportDeck reads a parameter file (schema bouncecal.params/1), maps its law onto the target's
// native law (mapping.hpp), picks the time step from the contact time and the error it costs in
// e (native_law.hpp), and writes into a new directory:
//   bounce:  in.bounce (LAMMPS, LIGGGHTS) or bounce.py (Yade): the fit's scene — the ball
//            released from rest at the drag-free height of the replay's first impact speed onto
//            a rigid plane z = 0, gravity, the native law — sampling trace.csv
//            (t_s,z_m,vz_m_s: the ball centre's height above the plane and its vertical
//            velocity, every <= 0.2 ms of simulated time);
//            run.sh runs the simulator found on PATH (lmp, liggghts, yade), fails loudly, and
//            turns trace.csv into impacts.csv (index,time_s,v_in_m_s,v_out_m_s) with
//            impacts.awk (impacts located from the exact gravity flights either side of each
//            contact); mapping.json is the ExportResult as JSON.
//   packing: in.packing (LAMMPS, LIGGGHTS): the seed paper's validation scene (docs/physics.md §1)
//            with the fitted damping; run.sh runs `mpirun -np ${NP:-1}`; writes packing.csv
//            (z_m of every sphere) and the density between 0.005 and 0.045 m.
//   column:  in.column (LAMMPS) or column.py (Yade) with column.data: seed 003's granular column
//            collapse (column.hpp, docs/column.md) with the fitted damping between beads and,
//            from options.column.wall_params, between beads and walls; run.sh (NP=N) runs it and
//            writes profile.csv, front.csv and summary.json; column.json is the plan.
// Refuses (Error) an unknown or newer schema, a fit whose outcome is not "converged" (unless
// options.force), an existing output directory (unless options.force), and a law the target
// cannot carry within options.max_e_error (unless options.allow_approximation). A converged fit
// with the warning law_misfit_small exports; the decks' header and mapping.json state that
// misfit beside the mapping's e error.
//
//   ExportOptions o; o.target = ExportTarget::kLammps;
//   ExportResult r = ExportDeck("params.json", "out/", o);
//   std::cout << DumpJson(ExportResultJson(r), 2);
#pragma once

#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/core/warning.hpp"
#include "bouncecal/export/column.hpp"
#include "bouncecal/export/mapping.hpp"

namespace bouncecal {

enum class ExportScene { kBounce, kPacking, kColumn };
const char* ExportSceneName(ExportScene scene);  // "bounce", "packing", "column"
bool ParseExportScene(const std::string& text, ExportScene* scene);

struct ExportOptions {
  ExportTarget target = ExportTarget::kLammps;
  ExportScene scene = ExportScene::kBounce;
  bool force = false;                // replace an existing directory; export an unconverged fit
  bool allow_approximation = false;  // accept a mapping whose e error exceeds max_e_error
  double max_e_error = 0.01;         // largest mapping error accepted without approximation
  int impacts = 10;                  // bounce: impacts the run covers
  double time_step_e_error = 5e-4;   // the time step is halved until its e error is below this
  // The version the deck is written for; "" = detect the simulator on PATH (the verified
  // version is assumed, with a note, when it is absent).
  std::string simulator_version;
  // packing scene (docs/physics.md §1): particles, simulated time.
  int packing_particles = 2000;
  double packing_time_s = 3.0;
  double packing_restitution = 0.0;  // pairwise e; 0 = the fit's e at the middle measured speed
  ColumnOptions column;              // column scene (column.hpp)
  bool IsValid(std::string* error) const;
};

struct ExportResult {
  std::string target;
  std::string scene;
  std::string simulator_version;
  std::string law;          // the law's name
  nlohmann::json law_json;  // the one law object (io/schema.hpp) as exported
  std::string native_law;
  std::string kind;  // exact, matched, approximated
  bool exact = false;
  double max_e_error = 0.0;
  double max_contact_time_error = 0.0;
  std::map<std::string, double> coefficients;
  double time_step_s = 0.0;
  double steps_per_contact = 0.0;  // shortest contact time / time step
  double time_step_e_error = 0.0;  // measured by FixedStepRestitution at v_min and v_max
  long steps = 0;
  double run_time_s = 0.0;           // simulated time
  int trace_every = 0;               // steps between trace samples
  double packing_restitution = 0.0;  // packing: the pairwise e used (0 for bounce)
  nlohmann::json column;             // column: the plan (beads, box, contacts, q_phi); else null
  std::vector<double> speeds_m_s;
  // The fitted law's own misfit, from the parameter file (fit.misfit_e, fit.misfit_tolerance_e;
  // NaN when the file does not give it): how far the law's e(v) is from a smoother e(v) through
  // the measured bounces, beside max_e_error, how far the simulator's law is from the fitted one.
  double law_misfit_e = std::numeric_limits<double>::quiet_NaN();
  double law_misfit_tolerance_e = std::numeric_limits<double>::quiet_NaN();
  std::vector<Warning> warnings;  // the fit's law_misfit_small, carried with its hint
  std::vector<std::string> notes;
  std::vector<std::string> files;
};

ExportResult ExportDeck(const std::string& params_path, const std::string& out_dir,
                        const ExportOptions& options);

// {target, scene, simulator_version, law, native_law, exact, max_e_error, notes[], ...}
nlohmann::json ExportResultJson(const ExportResult& result);

// The simulator's version string from the program on PATH ("" when it is not there).
std::string DetectSimulatorVersion(ExportTarget target);
// The program run.sh calls: lmp, liggghts, yade.
const char* SimulatorProgram(ExportTarget target);
// The Debian package that installs it: lammps, liggghts, yade.
const char* SimulatorPackage(ExportTarget target);

}  // namespace bouncecal

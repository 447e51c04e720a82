// export/column_deck.hpp — the column scene's writers and stages (internal to the export wing).
#pragma once

#include <string>
#include <vector>

#include "bouncecal/export/column.hpp"
#include "bouncecal/export/mapping.hpp"
#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal::exporter {

// column_scene.cpp: the geometry, bead sizes, counts, rest criterion and memory check (no
// contacts yet). Throws Error(kBadParameter) as PlanColumn.
ColumnPlan ColumnGeometry(const ColumnOptions& options, ExportTarget target);

// column_contact.cpp: a fit's mapping carried to the column (its constant e and the error
// against the fitted e(v) at the fit's speeds e_fit_at_speeds, measured on `body`).
ColumnFit MakeColumnFit(const std::string& params_path, const Mapping& mapping,
                        const ContactBody& body, const std::vector<double>& e_fit_at_speeds);
// LAMMPS' `damping tsuji` input e whose polynomial alpha(e) is `alpha` (Error when outside
// [0, 1.2728]).
double LammpsTsujiInput(double alpha);

// column_lammps.cpp, column_yade.cpp: the input decks; column_run.cpp: run.sh and column.awk.
std::string ColumnDataText(const ColumnPlan& plan, const std::vector<ColumnSphere>& spheres);
std::string LammpsColumnDeck(const ColumnPlan& plan, const std::vector<std::string>& comments);
std::string YadeColumnScript(const ColumnPlan& plan, const std::vector<std::string>& comments);
std::string ColumnRunScript(const ColumnPlan& plan);
std::string ColumnAwk();
// The plan's numbers as the JSON object export --json prints under "column".
std::vector<std::string> ColumnComments(const ColumnPlan& plan);

}  // namespace bouncecal::exporter

// bouncecal/physics/law_registry.hpp — every contact law by name, from one table.
//
//   std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);  // throws Error(kBadParameter)
//   for (const LawInfo& i : RegisteredLaws()) if (!i.needs_expression) ...
//
// The table itself (and the recipe for adding a law) is in src/physics/law_registry.cpp. Ask
// the row what a law can do (needs_expression, closed_forms, end_rule); never compare names.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

// How `bouncecal export` (export/mapping.hpp) carries a law into a DEM simulator's native laws.
enum class ExportMapping {
  kLinearDashpot,      // k, c: exact where the simulator ends the contact by the law's end rule,
                       // else k, c re-solved for the same e and contact time
  kConstantLinear,     // constant e and contact time: a linear spring-dashpot with the same ones
  kHertzTsuji,         // k, e: the simulator's Tsuji-damped Hertz law
  kHertzViscoelastic,  // k, A: native where the simulator has d^1/2 damping, else the closest
                       // constant-e Hertz law
  kClosestHertz,       // no native counterpart: the constant-e Hertz law closest to its e(v)
};

// One row of the registry table: a law's identity and capabilities.
struct LawInfo {
  std::string name;     // registry name, as typed in scene files and on the command line
  std::string summary;  // one line for `bouncecal laws`
  std::string formula;  // "F = k d + c d'"
  std::string source;   // paper + equation
  ContactEnd end_rule = ContactEnd::kOverlapZero;
  // The law is defined by LawSpec::expression (and its parameters are the expression's names).
  bool needs_expression = false;
  // Closed forms the law provides: "restitution", "contact_time", "solve_contact",
  // "damping_for_restitution", "restitution_gradient".
  std::vector<std::string> closed_forms;
  // Its export mapping, and for kConstantLinear why no native law carries it ("{target}" stands
  // for the simulator's name).
  ExportMapping export_mapping = ExportMapping::kClosestHertz;
  std::string export_note;

  bool HasClosedForm(const std::string& form) const;
};

// The spec `bouncecal laws` lists a law with: its name, and for a law defined by an expression
// (no fixed parameters) the example "k * d^1.5 * (1 + alpha * v)" with k = 1e10, alpha = 0.3.
LawSpec ExampleLawSpec(const std::string& name);

// Every registered law, in table order.
std::vector<LawInfo> RegisteredLaws();
// The row of a law by name; nullptr if unknown.
const LawInfo* FindLaw(const std::string& name);
// The law a force expression given without a law name selects (the first row that
// needs_expression).
std::string ExpressionLawName();

// Creates a law from its registry name and parameters by name; parameters not given take the
// law's defaults (some laws derive defaults from the body, e.g. Hertz stiffness from E* and
// R*). Unknown law, unknown parameter, non-finite or out-of-bounds value, bad expression:
// Error(kBadParameter) naming the law, the key and the value.
std::unique_ptr<ContactLaw> CreateLaw(const LawSpec& spec, const Scene& scene);

// The contact body of the scene (ball on a rigid wall: m* = m, R* = R).
ContactBody BodyFromScene(const Scene& scene);

}  // namespace bouncecal

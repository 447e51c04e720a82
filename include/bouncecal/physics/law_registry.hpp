// bouncecal/physics/law_registry.hpp — every contact law by name, from one table.
//
//   std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, body);  // throws Error(kBadParameter)
//   for (const LawInfo& i : RegisteredLaws()) ...
//
// The table itself (and the recipe for adding a law) is in src/physics/law_registry.cpp.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

struct LawInfo {
  std::string name;
  std::string summary;  // one line
};

// Every registered law, in table order.
std::vector<LawInfo> RegisteredLaws();

// Creates a law from its registry name and parameters by name; parameters not given take the
// law's defaults (some laws derive defaults from the body, e.g. Hertz stiffness from E* and
// R*). Unknown law, unknown parameter, non-finite or out-of-bounds value, bad expression:
// Error(kBadParameter) naming the law, the key and the value.
std::unique_ptr<ContactLaw> CreateLaw(const LawSpec& spec, const Scene& scene);

// The contact body of the scene (ball on a rigid wall: m* = m, R* = R).
ContactBody BodyFromScene(const Scene& scene);

}  // namespace bouncecal

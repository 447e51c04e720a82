// Force expressions (the expression law, muParser): CreateLaw and one contact's forces.
#include <cstddef>
#include <cstdint>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 4096) return 0;
  bouncecal::Scene scene;
  scene.law.name = "expression";
  scene.law.expression.assign(reinterpret_cast<const char*>(data), size);
  scene.law.parameters = {{"k", 1e7}, {"c", 10.0}};
  try {
    const auto law = bouncecal::CreateLaw(scene.law, scene);
    const auto p = law->ParameterValues();
    const auto dynamics = law->Dynamics(p, bouncecal::BodyFromScene(scene));
    for (double d : {0.0, 1e-6, 1e-4}) {
      for (double v : {-1.0, 0.0, 1.0}) (void)dynamics->Force(d, v, nullptr);
    }
  } catch (const bouncecal::Error&) {
  }
  return 0;
}

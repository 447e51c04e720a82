// Scene files (TOML): ParseScene, then Scene::IsValid and the law it names.
#include <cstddef>
#include <cstdint>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const bouncecal::Scene s = bouncecal::ParseScene(text, "fuzz.toml");
    std::string why;
    if (s.IsValid(&why)) (void)bouncecal::CreateLaw(s.law, s);
  } catch (const bouncecal::Error&) {
  }
  return 0;
}

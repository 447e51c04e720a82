// The bundled scene files (bundled_scenes.hpp), read from the text embedded at build time.
#include "bouncecal/physics/bundled_scenes.hpp"

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "physics/bundled_scene_files.hpp"

namespace bouncecal {

std::vector<std::string> BundledSceneNames() {
  std::vector<std::string> names;
  for (const bundled_scene_files::File& f : bundled_scene_files::Files()) {
    names.emplace_back(f.name);
  }
  return names;
}

std::string BundledSceneText(const std::string& name) {
  for (const bundled_scene_files::File& f : bundled_scene_files::Files()) {
    if (f.name == name) return std::string(f.text);
  }
  std::string known;
  for (const std::string& n : BundledSceneNames()) known += (known.empty() ? "" : ", ") + n;
  throw Error(ErrorCode::kBadParameter,
              "bundled scene '" + Abbreviate(name) + "': unknown (known: " + known + ")");
}

Scene BundledScene(const std::string& name) {
  return ParseScene(BundledSceneText(name), "data/scenes/" + name + ".toml");
}

}  // namespace bouncecal

// bouncecal/physics/bundled_scenes.hpp — the scene files shipped in data/scenes/, built into
// the library.
//
// data/scenes/*.toml is the one source of the bundled scenes' physical facts (ball, surface,
// drop, effects, law): CMake embeds the files at build time and they are parsed here with the
// scene-file parser (ParseScene), so the library needs no data directory at run time and a fact
// is never written twice (the synth presets take their scenes from here; tests/synth_test.cpp
// checks each preset's scene against its file).
//
//   Scene s = BundledScene("glass-glass");     // data/scenes/glass-glass.toml
//   for (const std::string& n : BundledSceneNames()) ...
#pragma once

#include <string>
#include <vector>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

// The bundled files' names (file name without ".toml"), sorted.
std::vector<std::string> BundledSceneNames();
// The file's text as shipped. Throws Error(kBadParameter) naming the known ones for an unknown
// name.
std::string BundledSceneText(const std::string& name);
// The file parsed by ParseScene; source is "data/scenes/NAME.toml". Throws as above, or
// Error(kBadScene) if the file is malformed (a build with such a file fails its tests).
Scene BundledScene(const std::string& name);

}  // namespace bouncecal

// The scene flags shared by analyze, simulate, synth and calibrate: --scene FILE plus
// overrides. The flags fill the library's SceneOverrides (bouncecal/io/given_scene.hpp), whose
// ResolveScene / ResolveGivenScene / AssumedValues do the rest; its messages name the
// SceneOverrides fields, which FlagText (output.hpp) maps back to these flags.
#pragma once

#include <CLI/CLI.hpp>

#include "bouncecal/io/given_scene.hpp"

namespace bouncecal::cli {

// Each flag is the SceneOverrides field of the same meaning (--height: height_m, --set:
// law_sets, ...).
using SceneFlags = SceneOverrides;

// Adds the scene flags to a subcommand. with_law adds --law/--set/--expression.
void AddSceneFlags(CLI::App* sub, SceneFlags* flags, bool with_law);

}  // namespace bouncecal::cli

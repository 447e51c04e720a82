// The scene flags shared by analyze, simulate, synth and calibrate (scene_flags.hpp): each
// fills the SceneOverrides field of the same meaning. Order of precedence, the checks and the
// messages: bouncecal/io/given_scene.hpp.
#include "scene_flags.hpp"

namespace bouncecal::cli {

void AddSceneFlags(CLI::App* sub, SceneFlags* flags, bool with_law) {
  sub->add_option("--scene", flags->scene_file, "scene file (TOML); flags override it");
  sub->add_option("--height", flags->height_m, "drop height of the ball's bottom, m");
  sub->add_option("--height-sigma", flags->height_sigma_m,
                  "1-sigma uncertainty of the drop height, m (default: the height is exact)");
  sub->add_option("--impact-speed", flags->impact_speed_m_s,
                  "first impact speed instead of a height, m/s");
  sub->add_option("--diameter", flags->diameter_m, "ball diameter, m");
  sub->add_option("--density", flags->density_kg_m3, "ball density, kg/m^3 (or --mass)");
  sub->add_option("--mass", flags->mass_kg, "ball mass, kg (or --density)");
  sub->add_option("--material", flags->material,
                  "ball material preset (steel, copper, glass, rubber, wood, pingpong, ...)");
  sub->add_option("--drag", flags->drag, "air drag: none, linear or quadratic");
  sub->add_flag("--buoyancy", flags->buoyancy, "correct gravity for air buoyancy");
  sub->add_flag(
      "--contact-duration", flags->contact_duration,
      "contact duration effect: intervals between onsets include each impact's contact time");
  sub->add_option("--g", flags->g_m_s2, "gravitational acceleration, m/s^2");
  if (with_law) {
    sub->add_option("--law", flags->law, "contact law (see `bouncecal laws`)");
    sub->add_option("--set", flags->law_sets,
                    "law parameter NAME=VALUE (repeatable: --set a=1 --set b=2)")
        ->allow_extra_args(false);
    sub->add_option("--expression", flags->expression,
                    "force expression for the \"expression\" law");
  }
}

}  // namespace bouncecal::cli

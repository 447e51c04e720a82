// export/deck.hpp — what every deck writer needs (internal to the export wing).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "bouncecal/core/format.hpp"
#include "bouncecal/export/export.hpp"
#include "bouncecal/export/mapping.hpp"
#include "bouncecal/io/param_resolved.hpp"

namespace bouncecal::exporter {

// Everything a deck states, resolved to numbers (SI units).
struct DeckInput {
  Mapping mapping;
  ExportOptions options;
  std::string law_summary;  // "hertz-tsuji: k = ..., e = ..." for the header
  std::string params_path;
  double radius_m = 0.0;
  double mass_kg = 0.0;
  double density_kg_m3 = 0.0;  // mass / volume, so the simulator's sphere has the fit's mass
  double poisson_ratio = 0.3;  // the ball's, for laws that take elastic constants
  double g_m_s2 = 9.8;
  double release_height_m = 0.0;  // ball bottom above the plane at t = 0 (rest)
  double time_step_s = 0.0;
  long steps = 0;
  int trace_every = 1;
  std::vector<std::string> comments;  // mapping, time step, notes: written as comment lines
  // packing scene
  double packing_restitution = 0.0;  // pairwise e the packing uses (the fit's, see export.cpp)
};

// A parameter file read, its fit outcome checked (unless force), replayed and mapped onto a
// target over its speeds (export.cpp's stages 1-2); e_fit: the fitted law's e at each speed.
struct MappedFile {
  ParamFile pf;
  Replay replay;
  std::unique_ptr<ContactLaw> law;
  ContactBody body;
  std::vector<double> speeds;
  Mapping mapping;
  std::vector<double> e_fit;
};
MappedFile MapParamFile(const std::string& path, ExportTarget target, bool force);
nlohmann::json ExportedLawJson(const ParamFile& pf, const ContactLaw& law, const Scene& scene);
// The output directory's checks (before any work) and its creation (after it).
void CheckOutputDirectory(const std::string& dir, bool force);
void PrepareOutputDirectory(const std::string& dir, bool force);
// The simulator version the deck is written for, and notes when it is not the verified one.
void AddVersionNotes(ExportResult* r, ExportTarget target, const std::string& requested);
// The column scene (column_export.cpp).
ExportResult ExportColumn(const std::string& params_path, const std::string& out_dir,
                          const ExportOptions& options);
// Comment lines with a prefix ("# ").
std::string CommentBlock(const std::vector<std::string>& lines, const std::string& prefix);

std::string LammpsBounceDeck(const DeckInput& in);
std::string LiggghtsBounceDeck(const DeckInput& in);
std::string YadeBounceScript(const DeckInput& in);
// Seed 002's packing scene (docs/physics.md §1): 1 cm steel spheres, k_n = k_s = 1e7 N/m,
// mu = 0.3, and the linear damping that gives restitution e: gamma_n = 2 zeta sqrt(kn/m*),
// zeta = -ln e / sqrt(ln^2 e + pi^2), with m* = m/2 between spheres and m* = m against a wall.
struct PackingScene {
  double kn = 1e7, mu = 0.3, d = 0.01, rho = 7800.0;
  double gn_pp = 0.0, gn_pw = 0.0;  // gamma_n (1/s): sphere-sphere, sphere-wall
  explicit PackingScene(double restitution);
};
std::string LammpsPackingDeck(const DeckInput& in);
std::string LiggghtsPackingDeck(const DeckInput& in);

// run.sh for a target and scene; impacts.awk; packing.awk.
std::string RunScript(const DeckInput& in);
std::string ImpactsAwk();
std::string PackingAwk();

}  // namespace bouncecal::exporter

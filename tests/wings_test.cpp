// The layout rule of the library's wings (README "Layout"): a wing includes only `core` and the
// wings listed before it in BOUNCECAL_WINGS (CMakeLists.txt: core acoustic physics fit synth io
// export report), so the pipeline reads bottom-up and nothing below knows what sits above it.
// `physics` and `acoustic` are independent of each other. The CLI (src/cli) may include any
// wing. The test reads every source and header of every wing and checks each project include.
// Nothing but the CLI knows the command line: no wing and no file of the Python bindings
// includes a src/cli header, and the bindings compile no src/cli file.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

std::vector<std::string> WingOrder() {
  std::vector<std::string> wings;
  std::stringstream in(BOUNCECAL_WING_ORDER);  // "core,acoustic,..." (CMakeLists.txt)
  for (std::string w; std::getline(in, w, ',');) wings.push_back(w);
  return wings;
}

// The wings each wing may include. acoustic and physics are siblings (neither needs the other).
std::map<std::string, std::set<std::string>> Allowed(const std::vector<std::string>& order) {
  std::map<std::string, std::set<std::string>> allowed;
  for (size_t i = 0; i < order.size(); ++i) {
    for (size_t j = 0; j <= i; ++j) allowed[order[i]].insert(order[j]);
  }
  allowed["physics"].erase("acoustic");
  return allowed;
}

struct Violation {
  std::string file, line;
};

std::vector<Violation> Violations(const std::string& wing, const std::set<std::string>& ok,
                                  const std::set<std::string>& all) {
  std::vector<Violation> out;
  const fs::path root(BOUNCECAL_SOURCE_DIR);
  // "bouncecal/<wing>/x.hpp" (public headers) or "<wing>/x.hpp" (private headers under src/).
  const std::regex include(R"re(^\s*#\s*include\s*"(?:bouncecal/)?([a-z_]+)/)re");
  for (const fs::path& dir : {root / "src" / wing, root / "include" / "bouncecal" / wing}) {
    if (!fs::exists(dir)) continue;
    for (const auto& entry : fs::recursive_directory_iterator(dir)) {
      if (!entry.is_regular_file()) continue;
      std::ifstream in(entry.path());
      for (std::string line; std::getline(in, line);) {
        std::smatch m;
        if (!std::regex_search(line, m, include)) continue;
        const std::string target = m[1];
        if (all.count(target) && !ok.count(target)) {
          out.push_back({fs::relative(entry.path(), root).string(), line});
        }
      }
    }
  }
  return out;
}

TEST(Wings, EachWingIncludesOnlyTheWingsBelowIt) {
  const std::vector<std::string> order = WingOrder();
  ASSERT_GE(order.size(), 6u) << BOUNCECAL_WING_ORDER;
  ASSERT_EQ(order.front(), "core");
  const std::set<std::string> all(order.begin(), order.end());
  const auto allowed = Allowed(order);
  size_t files_with_wings = 0;
  for (const std::string& wing : order) {
    files_with_wings += fs::exists(fs::path(BOUNCECAL_SOURCE_DIR) / "src" / wing) ? 1 : 0;
    for (const Violation& v : Violations(wing, allowed.at(wing), all)) {
      ADD_FAILURE() << v.file << " (wing " << wing << ") includes a wing above it: " << v.line;
    }
  }
  EXPECT_EQ(files_with_wings, order.size()) << "every listed wing has a src/ folder";
}

// The command line's files (src/cli/*.hpp) included by a file under `dir`.
std::vector<Violation> CliIncludes(const fs::path& dir) {
  std::set<std::string> cli_headers;
  for (const auto& entry : fs::directory_iterator(fs::path(BOUNCECAL_SOURCE_DIR) / "src" / "cli"))
    cli_headers.insert(entry.path().filename().string());
  std::vector<Violation> out;
  const std::regex include(R"re(^\s*#\s*include\s*"(?:cli/)?([A-Za-z0-9_.]+)")re");
  const std::regex cli_path(R"re(^\s*#\s*include\s*"cli/)re");
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path());
    for (std::string line; std::getline(in, line);) {
      std::smatch m;
      if (!std::regex_search(line, m, include)) continue;
      // A local include naming a CLI header ("scene_flags.hpp") or any "cli/..." path; the
      // bindings' own headers (python/src) do not share names with src/cli.
      const bool local_cli =
          cli_headers.count(m[1]) && !fs::exists(entry.path().parent_path() / std::string(m[1]));
      if (local_cli || std::regex_search(line, cli_path)) {
        out.push_back({fs::relative(entry.path(), BOUNCECAL_SOURCE_DIR).string(), line});
      }
    }
  }
  return out;
}

TEST(Wings, OnlyTheCommandLineKnowsTheCommandLine) {
  const fs::path root(BOUNCECAL_SOURCE_DIR);
  std::vector<fs::path> dirs = {root / "python" / "src"};
  for (const std::string& wing : WingOrder()) {
    dirs.push_back(root / "src" / wing);
    dirs.push_back(root / "include" / "bouncecal" / wing);
  }
  for (const fs::path& dir : dirs) {
    if (!fs::exists(dir)) continue;
    for (const Violation& v : CliIncludes(dir)) {
      ADD_FAILURE() << v.file << " includes a command-line header: " << v.line;
    }
  }
  std::ifstream in(root / "python" / "CMakeLists.txt");
  int lines = 0;
  for (std::string line; std::getline(in, line); ++lines) {
    const size_t hash = line.find('#');  // comments may talk about the CLI
    EXPECT_EQ(line.substr(0, hash).find("src/cli"), std::string::npos)
        << "python/CMakeLists.txt compiles or includes the command line: " << line;
  }
  EXPECT_GT(lines, 5);
}

// The check itself: a made-up wing list where fit sits below physics must flag fit's includes.
TEST(Wings, TheCheckFindsAnUpwardInclude) {
  const std::vector<std::string> order = {"core", "acoustic", "fit", "physics"};
  const std::set<std::string> all(order.begin(), order.end());
  const auto allowed = Allowed(order);
  EXPECT_FALSE(Violations("fit", allowed.at("fit"), all).empty())
      << "src/fit includes physics headers: with fit below physics that is a violation";
  EXPECT_TRUE(Violations("core", allowed.at("core"), all).empty());
}

}  // namespace

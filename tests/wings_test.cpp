// The layout rule of the library's wings (README "Layout"): a wing includes only `core` and the
// wings listed before it in BOUNCECAL_WINGS (CMakeLists.txt: core acoustic physics fit synth io
// export report), so the pipeline reads bottom-up and nothing below knows what sits above it.
// `physics` and `acoustic` are independent of each other. The CLI (src/cli) may include any
// wing. The test reads every source and header of every wing and checks each project include.
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

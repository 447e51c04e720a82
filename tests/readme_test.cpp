// The README's examples are real commands: every line "$ bouncecal ..." inside a fenced code
// block of README.md is run here with the built binary, from a scratch directory holding a copy
// of data/, and must exit with 0 (or with N where the line ends in "# exit N"). Commands with
// --json must print valid JSON. A README example that stops working fails this test.
// Where the README shows what a command prints (output lines after the "$ bouncecal" line in
// the same block), stdout must print exactly those lines; a "..." line stands for any number of
// lines, so the lines before it are compared with the first ones printed and the lines after it
// with the last ones. A number in the worked example that drifts fails the test;
// `python3 tools/update_readme_examples.py` rewrites the blocks from the current build.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace {
namespace fs = std::filesystem;

struct Example {
  int line = 0;
  std::string command;  // without "$ " and without the trailing "# exit N"
  int expected_exit = 0;
  std::vector<std::string> output;  // the printed lines the README shows (may hold "...")
};

std::vector<Example> ReadmeExamples() {
  std::ifstream in(fs::path(BOUNCECAL_SOURCE_DIR) / "README.md");
  std::vector<Example> out;
  std::string line;
  bool in_block = false, collecting = false;
  int n = 0;
  const std::regex exit_re(R"(\s+#\s*exit\s+(\d+)\s*$)");
  while (std::getline(in, line)) {
    ++n;
    if (line.rfind("```", 0) == 0) {
      in_block = !in_block;
      collecting = false;
      continue;
    }
    if (in_block && collecting && line.rfind("$ ", 0) != 0) {
      out.back().output.push_back(line);
      continue;
    }
    collecting = false;
    if (!in_block || line.rfind("$ bouncecal ", 0) != 0) continue;
    collecting = true;
    Example e;
    e.line = n;
    e.command = line.substr(2);
    std::smatch m;
    if (std::regex_search(e.command, m, exit_re)) {
      e.expected_exit = std::stoi(m[1].str());
      e.command = e.command.substr(0, static_cast<size_t>(m.position(0)));
    }
    out.push_back(e);
  }
  return out;
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

// The README's lines against what the command printed: head (before "...") and tail (after it).
void ExpectPrinted(const Example& e, const std::string& stdout_text) {
  const std::vector<std::string> got = Lines(stdout_text);
  const auto dots = std::find(e.output.begin(), e.output.end(), "...");
  const std::vector<std::string> head(e.output.begin(), dots);
  const std::vector<std::string> tail(dots == e.output.end() ? dots : dots + 1, e.output.end());
  if (dots == e.output.end()) {
    EXPECT_EQ(got.size(), e.output.size()) << "README.md:" << e.line << ": " << e.command;
  }
  ASSERT_GE(got.size(), head.size() + tail.size()) << "README.md:" << e.line << ": " << e.command;
  for (size_t k = 0; k < head.size(); ++k) {
    EXPECT_EQ(got[k], head[k]) << "README.md:" << e.line + 1 + static_cast<int>(k) << ": "
                               << e.command;
  }
  for (size_t k = 0; k < tail.size(); ++k) {
    EXPECT_EQ(got[got.size() - tail.size() + k], tail[k])
        << "README.md:" << e.line + 2 + static_cast<int>(head.size() + k) << ": " << e.command;
  }
}

TEST(Readme, ShowsPrintedOutputForTheWorkedExamples) {
  size_t with_output = 0;
  for (const auto& e : ReadmeExamples()) with_output += e.output.empty() ? 0 : 1;
  EXPECT_GE(with_output, 2u) << "the analyze and calibrate worked examples show their output";
}

TEST(Readme, HasExamplesOfEverySubcommand) {
  const auto examples = ReadmeExamples();
  for (const char* sub : {"detect", "analyze", "laws", "simulate", "calibrate", "synth"}) {
    bool found = false;
    for (const auto& e : examples) {
      if (e.command.rfind(std::string("bouncecal ") + sub, 0) == 0) found = true;
    }
    EXPECT_TRUE(found) << "README.md has no '$ bouncecal " << sub << "' example";
  }
}

TEST(Readme, EveryExampleRunsAsDocumented) {
  const fs::path dir =
      fs::path(::testing::TempDir()) / ("bouncecal_readme_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  fs::copy(fs::path(BOUNCECAL_SOURCE_DIR) / "data", dir / "data", fs::copy_options::recursive);
  const std::string binary = BOUNCECAL_BINARY;
  int index = 0;
  for (const auto& e : ReadmeExamples()) {
    const fs::path out = dir / ("out" + std::to_string(index));
    const fs::path err = dir / ("err" + std::to_string(index));
    ++index;
    const std::string cmd = "cd '" + dir.string() + "' && '" + binary + "'" +
                            e.command.substr(std::string("bouncecal").size()) + " >'" +
                            out.string() + "' 2>'" + err.string() + "' </dev/null";
    const int status = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(status)) << "README.md:" << e.line << ": " << e.command;
    EXPECT_EQ(WEXITSTATUS(status), e.expected_exit)
        << "README.md:" << e.line << ": " << e.command << "\nstderr: " << ReadAll(err);
    if (!e.output.empty()) ExpectPrinted(e, ReadAll(out));
    if (e.expected_exit == 0 && e.command.find("--json") != std::string::npos) {
      const std::string text = ReadAll(out);
      bool ok = true;
      // --batch --json prints one JSON object per line.
      if (e.command.find("--batch") != std::string::npos) {
        std::istringstream lines(text);
        std::string l;
        while (std::getline(lines, l)) ok = ok && nlohmann::json::accept(l);
      } else {
        ok = nlohmann::json::accept(text);
      }
      EXPECT_TRUE(ok) << "README.md:" << e.line << ": --json output is not JSON";
    }
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace

// Every command's JSON output validates against its documented schema (docs/schema/*.json,
// docs/schema.md), and every --csv follows the CSV conventions (header, shortest round-trip
// numbers, empty = absent, a file column for several files). Runs the built binary on the
// bundled recording, its scene, a synth recording and a fit's parameter file.
// The validator (json_schema.hpp) rejects unknown keys, missing keys and nulls in non-null
// fields: a command that adds, renames or nulls a documented field fails here.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "json_schema.hpp"
#include "test_util.hpp"

namespace {

using bouncecal::testing_util::CommandResult;
using bouncecal::testing_util::RunCommand;
using bouncecal::testing_util::SchemaSet;
using bouncecal::testing_util::ScratchDir;
using bouncecal::testing_util::Slurp;
using nlohmann::json;

const std::string kBin = BOUNCECAL_BINARY;
const std::string kSrc = BOUNCECAL_SOURCE_DIR;
const std::string kFlac = kSrc + "/data/default_steel_copper.flac";
const std::string kScene = kSrc + "/data/default_steel_copper.toml";

const SchemaSet& Schemas() {
  static const SchemaSet set(kSrc + "/docs/schema");
  return set;
}

// "bouncecal.detect/2" -> "detect.schema.json" (the file whose $id it is).
std::string SchemaFile(const json& j) {
  if (!j.is_object() || !j.contains("schema") || !j["schema"].is_string()) return "";
  const std::string id = j["schema"].get<std::string>();
  const std::string name = id.substr(std::string("bouncecal.").size(), id.find('/') - 10);
  return name + ".schema.json";
}

std::string Errors(const std::vector<std::string>& e) {
  std::string out;
  for (const auto& s : e) out += s + "\n";
  return out;
}

// Validates one output object against the schema its "schema" key names (and that the file's
// $id is that exact version).
void ExpectValid(const json& j, const std::string& expected_schema) {
  ASSERT_TRUE(j.is_object()) << j.dump().substr(0, 200);
  ASSERT_EQ(j.value("schema", ""), expected_schema);
  const std::string file = SchemaFile(j);
  ASSERT_TRUE(Schemas().Has(file)) << file;
  EXPECT_EQ(Schemas().Validate(j, file).size(), 0u) << Errors(Schemas().Validate(j, file));
}

json RunJson(const std::string& args, int expected_exit = 0) {
  const CommandResult r = RunCommand(kBin, args);
  EXPECT_EQ(r.exit_code, expected_exit) << args << "\n" << r.err;
  return json::parse(r.out, nullptr, false);
}

std::vector<std::vector<std::string>> ParseCsv(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> row;
  std::string field;
  bool quoted = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"' && i + 1 < text.size() && text[i + 1] == '"') {
        field += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        field += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      row.push_back(field);
      field.clear();
    } else if (c == '\n') {
      row.push_back(field);
      rows.push_back(row);
      row.clear();
      field.clear();
    } else {
      field += c;
    }
  }
  return rows;
}

// The CSV of `args`: a header, every row as wide as it, no "nan"/"inf" field (absent = empty).
std::vector<std::vector<std::string>> RunCsv(const std::string& args) {
  const CommandResult r = RunCommand(kBin, args);
  EXPECT_EQ(r.exit_code, 0) << args << "\n" << r.err;
  auto rows = ParseCsv(r.out);
  EXPECT_GE(rows.size(), 2u) << args;
  for (const auto& row : rows) {
    EXPECT_EQ(row.size(), rows.front().size()) << args;
    for (const auto& f : row) {
      EXPECT_NE(f, "nan") << args;
      EXPECT_NE(f, "inf") << args;
    }
  }
  return rows;
}

int Column(const std::vector<std::string>& header, const std::string& name) {
  const auto it = std::find(header.begin(), header.end(), name);
  EXPECT_NE(it, header.end()) << name;
  return static_cast<int>(it - header.begin());
}

// A CSV number reads back to exactly the JSON number (round-trip precision).
void ExpectSameNumber(const std::string& csv, const json& j, const std::string& what) {
  if (j.is_null()) {
    EXPECT_EQ(csv, "") << what << ": absent must be empty";
    return;
  }
  ASSERT_FALSE(csv.empty()) << what;
  EXPECT_EQ(std::stod(csv), j.get<double>()) << what << ": " << csv;
}

class SchemaTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("bc_schema");
    // A second recording (synth) and a fit's parameter file, shared by the tests.
    const CommandResult s = RunCommand(kBin, "synth --seed 5 --json -o " + (*dir_ / "synth.wav"));
    ASSERT_EQ(s.exit_code, 0) << s.err;
    synth_json_ = new json(json::parse(s.out));
    const CommandResult c = RunCommand(kBin, "calibrate " + kFlac + " --scene " + kScene +
                                                 " --quiet -o " + (*dir_ / "params.json"));
    ASSERT_EQ(c.exit_code, 0) << c.err;
  }
  static void TearDownTestSuite() {
    delete synth_json_;
    delete dir_;
  }
  static std::string P(const std::string& name) { return *dir_ / name; }
  static ScratchDir* dir_;
  static json* synth_json_;
};
ScratchDir* SchemaTest::dir_ = nullptr;
json* SchemaTest::synth_json_ = nullptr;

TEST(SchemaFiles, EverySchemaFileNamesItsVersionAndTheValidatorCatchesChanges) {
  // The validator itself: a renamed, an added and a nulled field each fail.
  const json good = RunJson("detect " + kFlac + " --json");
  ExpectValid(good, "bouncecal.detect/2");
  json renamed = good;
  json& first = renamed["sequences"][0]["impacts"][0];
  first["sigma_s"] = first["time_sigma_s"];
  first.erase("time_sigma_s");
  EXPECT_GE(Schemas().Validate(renamed, "detect.schema.json").size(), 2u);
  json added = good;
  added["channel_used"] = 0;
  EXPECT_EQ(Schemas().Validate(added, "detect.schema.json").size(), 1u);
  json nulled = good;
  nulled["sequences"][0]["impacts"][0]["time_s"] = nullptr;
  EXPECT_EQ(Schemas().Validate(nulled, "detect.schema.json").size(), 1u);
  // bouncecal.detect/1's second copy of the impacts is gone (each impact once, in its sequence).
  json second_copy = good;
  second_copy["impacts"] = good["sequences"][0]["impacts"];
  EXPECT_EQ(Schemas().Validate(second_copy, "detect.schema.json").size(), 1u);
  json wrong_version = good;
  wrong_version["schema"] = "bouncecal.detect/1";
  EXPECT_EQ(Schemas().Validate(wrong_version, "detect.schema.json").size(), 1u);
}

TEST_F(SchemaTest, Detect) {
  ExpectValid(RunJson("detect " + kFlac + " --json"), "bouncecal.detect/2");
  // Several recordings: an array; a failed one is a bouncecal.error/1 object.
  const json all =
      RunJson("detect " + kFlac + " " + P("synth.wav") + " " + P("absent.wav") + " --json", 12);
  ASSERT_EQ(all.size(), 3u);
  ExpectValid(all[0], "bouncecal.detect/2");
  ExpectValid(all[1], "bouncecal.detect/2");
  ExpectValid(all[2], "bouncecal.error/1");
  EXPECT_EQ(all[2]["error"]["exit_code"], 3);
  // CSV: the same numbers to the last bit; a file column for several files.
  const auto rows = RunCsv("detect " + kFlac + " --csv");
  const auto& h = rows.front();
  EXPECT_EQ(h.front(), "sequence");
  const json& first = all[0]["sequences"][0]["impacts"];
  ASSERT_GE(rows.size(), first.size() + 1);
  for (size_t k = 0; k < first.size(); ++k) {
    ExpectSameNumber(rows[k + 1][Column(h, "time_s")], first[k]["time_s"], "time_s");
    ExpectSameNumber(rows[k + 1][Column(h, "time_sigma_s")], first[k]["time_sigma_s"],
                     "time_sigma_s");
  }
  const auto two = RunCsv("detect " + kFlac + " " + P("synth.wav") + " --csv");
  EXPECT_EQ(two.front().front(), "file");
  EXPECT_EQ(two[1][0], kFlac);
}

TEST_F(SchemaTest, Analyze) {
  const json a = RunJson("analyze " + kFlac + " --scene " + kScene + " --json");
  ExpectValid(a, "bouncecal.analysis/1");
  EXPECT_EQ(a["scene"]["effects"]["contact_duration"], true);
  EXPECT_TRUE(a["bounces"][1]["contact_s"].is_number());
  // No scene: drop unknown (null), contact duration off (contact_s null, not 0).
  const json n = RunJson("analyze " + kFlac + " --json");
  ExpectValid(n, "bouncecal.analysis/1");
  EXPECT_TRUE(n["scene"]["drop"]["height_m"].is_null());
  for (const json& b : n["bounces"]) EXPECT_TRUE(b["contact_s"].is_null());
  const json two = RunJson("analyze " + kFlac + " " + P("synth.wav") + " --json");
  ASSERT_EQ(two.size(), 2u);
  for (const json& j : two) ExpectValid(j, "bouncecal.analysis/1");
  // CSV: round trip of e and its sigma; contact_s empty when off; file column for several.
  const auto rows = RunCsv("analyze " + kFlac + " --scene " + kScene + " --csv");
  const auto& h = rows.front();
  for (size_t k = 0; k < a["bounces"].size(); ++k) {
    ExpectSameNumber(rows[k + 1][Column(h, "e")], a["bounces"][k]["e"], "e");
    ExpectSameNumber(rows[k + 1][Column(h, "e_sigma")], a["bounces"][k]["e_sigma"], "e_sigma");
    ExpectSameNumber(rows[k + 1][Column(h, "contact_s")], a["bounces"][k]["contact_s"],
                     "contact_s");
  }
  const auto off = RunCsv("analyze " + kFlac + " --csv");
  for (size_t k = 1; k < off.size(); ++k) EXPECT_EQ(off[k][Column(off[0], "contact_s")], "");
  EXPECT_EQ(RunCsv("analyze " + kFlac + " " + P("synth.wav") + " --csv").front().front(), "file");
}

TEST_F(SchemaTest, SimulateAndLaws) {
  const json s = RunJson("simulate --scene " + kScene + " --max-impacts 5 --json");
  ExpectValid(s, "bouncecal.simulation/1");
  ExpectValid(RunJson("simulate --params " + P("params.json") + " --max-impacts 5 --json"),
              "bouncecal.simulation/1");
  ExpectValid(RunJson("simulate --law expression --expression 'k*d^1.5*(1+a*v)' --set k=1e10 "
                      "--set a=0.3 --max-impacts 3 --json"),
              "bouncecal.simulation/1");
  const auto rows = RunCsv("simulate --scene " + kScene + " --max-impacts 5 --csv");
  ASSERT_EQ(rows.size(), 6u);
  for (size_t k = 0; k < 5; ++k) {
    ExpectSameNumber(rows[k + 1][Column(rows[0], "time_s")], s["impacts"][k]["time_s"], "t");
    ExpectSameNumber(rows[k + 1][Column(rows[0], "e")], s["impacts"][k]["e"], "e");
  }
  const json laws = RunJson("laws --json");
  ExpectValid(laws, "bouncecal.laws/1");
  // laws --csv: one row per parameter of every law, the same defaults as --json.
  const auto csv = RunCsv("laws --csv");
  size_t n = 0;
  for (const json& l : laws["laws"]) n += l["parameters"].size();
  ASSERT_EQ(csv.size(), n + 1);
  for (size_t r = 1; r < csv.size(); ++r) {
    const json* law = nullptr;
    for (const json& l : laws["laws"])
      if (l["name"] == csv[r][0]) law = &l;
    ASSERT_NE(law, nullptr) << csv[r][0];
    ExpectSameNumber(csv[r][Column(csv[0], "default")], (*law)["parameters"][csv[r][1]]["value"],
                     csv[r][0] + "." + csv[r][1]);
  }
}

TEST_F(SchemaTest, Calibrate) {
  const json c = RunJson("calibrate " + kFlac + " --scene " + kScene + " --quiet --json");
  ExpectValid(c, "bouncecal.params/2");
  ExpectValid(json::parse(Slurp(P("params.json"))), "bouncecal.params/2");
  // --batch --json: one bouncecal.calibration_row/1 per line, failures included.
  const CommandResult b = RunCommand(kBin, "calibrate " + kFlac + " " + P("absent.wav") +
                                               " --scene " + kScene + " --batch --json --quiet");
  EXPECT_EQ(b.exit_code, 12) << b.err;
  std::istringstream lines(b.out);
  std::vector<json> rows;
  for (std::string line; std::getline(lines, line);) rows.push_back(json::parse(line));
  ASSERT_EQ(rows.size(), 2u);
  for (const json& r : rows) ExpectValid(r, "bouncecal.calibration_row/1");
  EXPECT_EQ(rows[0]["status"], "ok");
  EXPECT_EQ(rows[0]["law"]["parameters"], c["law"]["parameters"]);
  EXPECT_EQ(rows[1]["status"], "error");
  EXPECT_EQ(rows[1]["error"]["exit_code"], 3);
  // --csv: the fitted values to the last bit.
  const auto csv = RunCsv("calibrate " + kFlac + " --scene " + kScene + " --quiet --csv");
  for (const auto& [name, p] : c["law"]["parameters"].items()) {
    ExpectSameNumber(csv[1][Column(csv[0], name)], p["value"], name);
    ExpectSameNumber(csv[1][Column(csv[0], name + "_sigma")], p["sigma"], name + "_sigma");
  }
}

TEST_F(SchemaTest, CalibrateLawAll) {
  const json all = RunJson("calibrate " + kFlac + " --scene " + kScene + " --law all --json");
  ExpectValid(all, "bouncecal.law_comparison/2");
  ASSERT_FALSE(all["laws"].empty());
  for (const json& l : all["laws"]) EXPECT_EQ(l["schema"], "bouncecal.params/2");
}

TEST_F(SchemaTest, SynthExportReport) {
  ExpectValid(*synth_json_, "bouncecal.synth/1");
  const json e = RunJson("export " + P("params.json") + " --to lammps -o " + P("lmp") + " --json");
  ExpectValid(e, "bouncecal.export/2");
  ExpectValid(json::parse(Slurp(P("lmp") + "/mapping.json")), "bouncecal.export/2");
  const json params = json::parse(Slurp(P("params.json")));
  EXPECT_EQ(e["law"], params["law"]);
  // The report's embedded data.
  const CommandResult r =
      RunCommand(kBin, "report " + kFlac + " --scene " + kScene + " --quiet -o " + P("r.html"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = Slurp(P("r.html"));
  const std::string open = "id=\"bouncecal-data\">";
  const size_t a = html.find(open);
  ASSERT_NE(a, std::string::npos);
  const size_t b = html.find("</script>", a);
  const json d = json::parse(html.substr(a + open.size(), b - a - open.size()));
  ExpectValid(d, "bouncecal.report/2");
  EXPECT_EQ(d["fit"]["law"]["name"], params["law"]["name"]);
}

}  // namespace

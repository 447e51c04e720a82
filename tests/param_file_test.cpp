// Parameter file (schema bouncecal.params/2) and provenance: keys and types, null sigmas,
// write/read round trip, atomic writing, refusal to overwrite inputs or existing files,
// --force, missing directories, malformed files; SHA-256 against published test vectors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

class TempDir : public testing_util::ScratchDir {
 public:
  TempDir() : ScratchDir("bc_param") {}
  size_t Count() const {
    return static_cast<size_t>(std::distance(fs::directory_iterator(path()), {}));
  }
};

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A real (small) calibration: walton-braun gamma = 0.408 from 10 simulated impacts, fitted as
// simulated (trajectory strategy: the intervals include the contacts).
const Calibration& SampleFit() {
  static const Calibration c = [] {
    Scene s;
    s.law.parameters = {{"gamma", 0.408}};
    auto law = CreateLaw(s.law, s);
    s.limits.max_impacts = 10;
    const Simulation sim = Simulate(s, *law, law->ParameterValues());
    Sequence seq;
    for (const auto& i : sim.impacts) seq.impacts.push_back({1.0 + i.time_s, 5e-6});
    Scene start;
    CalibrationOptions o;
    o.strategy = FitStrategy::kTrajectory;
    return Calibrate({{"drop.wav", seq}}, start, o);
  }();
  return c;
}

TEST(Provenance, Sha256MatchesPublishedVectors) {
  // FIPS 180-2 examples.
  EXPECT_EQ(Sha256OfString("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256OfString(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  TempDir dir;
  WriteText(dir / "abc.txt", "abc");
  EXPECT_EQ(Sha256OfFile(dir / "abc.txt"), Sha256OfString("abc"));
  // Larger than one read buffer.
  const std::string big(200000, 'x');
  WriteText(dir / "big.bin", big);
  EXPECT_EQ(Sha256OfFile(dir / "big.bin"), Sha256OfString(big));
  try {
    Sha256OfFile(dir / "missing.wav");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInputMissing);
    EXPECT_NE(std::string(e.what()).find("missing.wav"), std::string::npos);
  }
}

TEST(Provenance, DatesAreIsoUtcAndVersionIsSet) {
  EXPECT_EQ(IsoDateUtc(0), "1970-01-01T00:00:00Z");
  EXPECT_EQ(IsoDateUtc(1700000000), "2023-11-14T22:13:20Z");
  EXPECT_EQ(NowIsoDateUtc().size(), 20u);
  EXPECT_EQ(BouncecalVersion(), BOUNCECAL_VERSION);
  TempDir dir;
  WriteText(dir / "a.wav", "abc");
  const Provenance p = MakeProvenance({dir / "a.wav"});
  ASSERT_EQ(p.inputs.size(), 1u);
  EXPECT_EQ(p.inputs[0].sha256, Sha256OfString("abc"));
}

TEST(ParamFile, SchemaKeysAndTypes) {
  const Calibration& c = SampleFit();
  Provenance prov;
  prov.inputs = {{"drop.wav", Sha256OfString("x")}};
  prov.bouncecal_version = "9.9.9";
  prov.date_utc = "2026-01-01T00:00:00Z";
  const json j = CalibrationJson(c, prov, OptionsJson(CalibrationOptions{}));
  EXPECT_EQ(j.at("schema"), "bouncecal.params/2");
  EXPECT_EQ(j.at("law").at("name"), "walton-braun");
  const json& gamma = j.at("law").at("parameters").at("gamma");
  EXPECT_TRUE(gamma.at("value").is_number());
  EXPECT_TRUE(gamma.at("sigma").is_number());
  EXPECT_EQ(gamma.at("unit"), "1");
  EXPECT_EQ(gamma.at("fixed"), false);
  EXPECT_NEAR(gamma.at("value").get<double>(), 0.408, 1e-4);
  const json& k = j.at("law").at("parameters").at("k");
  EXPECT_EQ(k.at("fixed"), true);
  EXPECT_TRUE(k.at("sigma").is_null());  // held: no sigma, never NaN
  EXPECT_EQ(k.at("unit"), "N/m");
  ASSERT_GE(j.at("e_of_v").size(), 2u);
  for (const auto& pt : j.at("e_of_v")) {
    EXPECT_TRUE(pt.at("v_m_s").is_number());
    EXPECT_TRUE(pt.at("e").is_number());
    EXPECT_TRUE(pt.at("e_sigma").is_number());
  }
  // Tabulated over the measured speed range.
  EXPECT_NEAR(j["e_of_v"].front()["v_m_s"].get<double>(), c.v_min_m_s, 1e-12);
  EXPECT_NEAR(j["e_of_v"].back()["v_m_s"].get<double>(), c.v_max_m_s, 1e-9);
  const json& fit = j.at("fit");
  for (const char* key : {"strategy", "rms_residual_s", "chi2_dof", "outcome", "iterations",
                          "determined", "undetermined", "aic", "bic", "dof", "reason", "exit_code",
                          "scatter_e", "scatter_e_sigma", "starts"}) {
    EXPECT_TRUE(fit.contains(key)) << key;
  }
  EXPECT_EQ(fit.at("strategy"), "trajectory");
  EXPECT_EQ(fit.at("outcome"), "converged");
  EXPECT_EQ(fit.at("exit_code"), 0);
  EXPECT_TRUE(fit.at("scatter_e").is_number());
  EXPECT_TRUE(j.at("warnings").is_array());
  EXPECT_EQ(fit.at("determined"), json::array({"gamma"}));
  for (const char* key : {"source", "ball", "surface", "environment", "drop", "effects"}) {
    EXPECT_TRUE(j.at("scene").contains(key)) << key;
  }
  EXPECT_NEAR(j["scene"]["ball"]["diameter_m"].get<double>(), 0.01, 1e-15);
  EXPECT_EQ(j["scene"]["effects"]["drag"], "none");
  const json& pv = j.at("provenance");
  EXPECT_EQ(pv.at("inputs")[0].at("file"), "drop.wav");
  EXPECT_EQ(pv.at("inputs")[0].at("sha256"), Sha256OfString("x"));
  EXPECT_EQ(pv.at("bouncecal_version"), "9.9.9");
  EXPECT_EQ(pv.at("date_utc"), "2026-01-01T00:00:00Z");
  EXPECT_EQ(pv.at("options").at("strategy"), "restitution");  // the options passed in
  EXPECT_EQ(j.at("recordings")[0].at("file"), "drop.wav");
  EXPECT_TRUE(j.at("recordings")[0].at("time_origin_s").is_number());
  // Restitution fits name their RMS in e.
  Calibration r = c;
  r.strategy = FitStrategy::kRestitution;
  const json jr = CalibrationJson(r, prov, json::object());
  EXPECT_TRUE(jr.at("fit").contains("rms_residual_e"));
  EXPECT_FALSE(jr.at("fit").contains("rms_residual_s"));
}

TEST(ParamFile, WriteReadRoundTripFeedsCreateLaw) {
  TempDir dir;
  const Calibration& c = SampleFit();
  const json j = CalibrationJson(c, MakeProvenance({}), OptionsJson({}));
  WriteParamFile(dir / "params.json", j, {});
  EXPECT_EQ(dir.Count(), 1u);  // no temporary left behind
  const ParamFile p = ReadParamFile(dir / "params.json");
  EXPECT_EQ(p.schema, kParamFileSchema);
  EXPECT_EQ(p.law.name, "walton-braun");
  EXPECT_EQ(p.outcome, "converged");
  ASSERT_EQ(p.warnings.size(), c.warnings.size());  // the codes read back, in order
  for (size_t i = 0; i < c.warnings.size(); ++i) EXPECT_EQ(p.warnings[i], c.warnings[i].code);
  EXPECT_DOUBLE_EQ(p.law.parameters.at("gamma"), c.parameters[1].value);
  EXPECT_TRUE(p.sigma.count("gamma"));
  EXPECT_FALSE(p.sigma.count("k"));
  Scene s;
  auto law = CreateLaw(p.law, s);
  EXPECT_DOUBLE_EQ(law->ParameterValues()[1], c.parameters[1].value);
  EXPECT_EQ(ReadText(dir / "params.json").back(), '\n');
}

TEST(ParamFile, RefusesToOverwriteInputsOrExistingFilesWithoutForce) {
  TempDir dir;
  const json j = CalibrationJson(SampleFit(), MakeProvenance({}), json::object());
  WriteText(dir / "drop.wav", "RIFF....");
  // The output is one of the inputs: refused even with --force, input untouched.
  for (bool force : {false, true}) {
    try {
      WriteParamFile(dir / "drop.wav", j, {.force = force, .inputs = {dir / "drop.wav"}});
      ADD_FAILURE();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kOutput);
      EXPECT_NE(std::string(e.what()).find("input"), std::string::npos) << e.what();
    }
    EXPECT_EQ(ReadText(dir / "drop.wav"), "RIFF....");
  }
  // An existing output: refused without force, replaced with it.
  WriteText(dir / "params.json", "old");
  try {
    WriteParamFile(dir / "params.json", j, {});
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kOutput);
    EXPECT_NE(std::string(e.what()).find("exists and WriteOptions::force is false"),
              std::string::npos)
        << e.what();
  }
  EXPECT_EQ(ReadText(dir / "params.json"), "old");
  WriteParamFile(dir / "params.json", j, {.force = true, .inputs = {}});
  EXPECT_EQ(json::parse(ReadText(dir / "params.json")).at("schema"), kParamFileSchema);
  EXPECT_EQ(dir.Count(), 2u);
}

TEST(ParamFile, MissingDirectoryIsAnOutputError) {
  TempDir dir;
  const std::string path = dir / "no/such/dir/params.json";
  try {
    WriteParamFile(path, json::object(), {});
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kOutput);
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos);
  }
  EXPECT_THROW(CheckOutputPath(path), Error);
  EXPECT_EQ(dir.Count(), 0u);
}

TEST(ParamFile, MalformedFilesAreRejectedWithTheKey) {
  TempDir dir;
  auto expect_bad = [&](const std::string& text, const std::string& needle) {
    WriteText(dir / "p.json", text);
    try {
      ReadParamFile(dir / "p.json");
      ADD_FAILURE() << text;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kBadParameter) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("p.json"), std::string::npos) << e.what();
    }
  };
  // A syntax error names where parsing stopped (was "not a JSON object" for any of these).
  expect_bad("not json", "syntax error at line 1, column 2");
  expect_bad("{\n  \"schema\": \"bouncecal.params/2\",\n  \"law\": {\"name\": ",
             "syntax error at line 3, column 19 (the text ends early)");
  expect_bad("{\"a\": 1,\n\"b\" 2}", "syntax error at line 2, column 5");
  expect_bad("", "empty file (0 bytes)");
  // A number beyond a double's range (CI's fuzz stage: "2e421" escaped as nlohmann's
  // out_of_range and aborted the reader).
  expect_bad("2e421", "beyond a double's range");
  expect_bad(R"({"schema": "bouncecal.params/2", "x": 1e999})", "beyond a double's range");
  expect_bad("[1,2]", "not a JSON object");
  expect_bad(R"({"law": "walton-braun"})", "schema");
  expect_bad(R"({"schema": "bouncecal.params/3", "law": {"name": "x", "parameters": {}}})",
             "bouncecal.params/3");
  expect_bad(R"({"schema": "bouncecal.params/2", "law": "walton-braun"})", "law.name");
  expect_bad(R"({"schema": "bouncecal.params/2", "law": {"name": "walton-braun"}})",
             "law.parameters");
  expect_bad(
      R"({"schema": "bouncecal.params/2", "law": {"name": "walton-braun",
          "parameters": {"gamma": {"value": null}}}})",
      "law.parameters.gamma.value");
  // Version 1 files (law a name, parameters at the top level) are still read, checked alike.
  expect_bad(R"({"schema": "bouncecal.params/1", "parameters": {}})", "law");
  expect_bad(R"({"schema": "bouncecal.params/1", "law": "walton-braun"})", "parameters");
  expect_bad(
      R"({"schema": "bouncecal.params/1", "law": "walton-braun",
          "parameters": {"gamma": {"value": "0.4"}}})",
      "parameters.gamma.value");
  // A missing file and a directory are kInputMissing, as for recordings and scenes (a
  // directory was "not a JSON object", exit 9: std::ifstream opens a directory on Linux).
  fs::create_directory(dir / "adir");
  for (const auto& [name, needle] :
       {std::pair<std::string, std::string>{"absent.json", "parameter file does not exist"},
        {"adir", "is a directory"}}) {
    try {
      ReadParamFile(dir / name);
      ADD_FAILURE() << name;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInputMissing) << e.what();
      EXPECT_NE(std::string(e.what()).find(dir / name + ": " + needle), std::string::npos)
          << e.what();
    }
  }
}

TEST(ParamFile, OptionsJsonRecordsEveryKnob) {
  CalibrationOptions o;
  o.strategy = FitStrategy::kRestitution;
  o.free_parameters = {"k"};
  o.derivatives = DerivativeMode::kNumeric;
  o.rel_tolerance = 1e-7;
  o.loss = RobustLoss::kCauchy;
  const json j = OptionsJson(o);
  EXPECT_EQ(j.at("strategy"), "restitution");
  EXPECT_EQ(j.at("free_parameters"), json::array({"k"}));
  EXPECT_EQ(j.at("derivatives"), "numeric");
  EXPECT_DOUBLE_EQ(j.at("rel_tolerance").get<double>(), 1e-7);
  EXPECT_EQ(j.at("loss"), "cauchy");
  EXPECT_TRUE(j.contains("use_drop"));
  EXPECT_TRUE(j.contains("max_iterations"));
}

}  // namespace
}  // namespace bouncecal

// The contact-law registry: one table, name -> factory (law_registry.hpp).
#include "bouncecal/physics/law_registry.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "physics/laws/law_base.hpp"

namespace bouncecal {

namespace laws {
// Factories, one per law file in src/physics/laws/.
std::unique_ptr<LawBase> MakeLinearDashpot(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeLinearDashpotForceZero(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeWaltonBraun(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeWaltonBraunHysteretic(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHertzTsuji(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHertzViscoelastic(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHuntCrossley(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHuntCrossleyHC(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHuntCrossleyLN(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeHuntCrossleyFlores(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeJiangLiu(const LawSpec&, const Scene&);
std::unique_ptr<LawBase> MakeExpression(const LawSpec&, const Scene&);
}  // namespace laws

namespace {

struct LawRow {
  const char* name;     // registry name, as typed in scene files and on the command line
  const char* summary;  // one line for `bouncecal laws`
  laws::LawFactory make;
};

// ================================================================================================
// THE TABLE. To add a contact law:
//   1. write src/physics/laws/<name>.cpp with a class deriving from laws::LawBase
//   (laws/law_base.hpp):
//      Name/Formula/Source, specs_ (name, unit, bounds, default, damping flag) set in the
//      constructor, Force and ElasticEnergy (templated on the scalar type where a closed form
//      wants derivatives), closed forms where they exist, ClosedForms() listing them;
//   2. give it a factory `std::unique_ptr<LawBase> MakeX(const LawSpec&, const Scene&)`, declare
//      it above, and add ONE row below;
//   3. add its oracle test to tests/laws_test.cpp (closed form vs the independent integrator).
// Parameters are set by name by CreateLaw (unknown names, NaN, out-of-bounds values are
// rejected there), so a factory only declares them. Keep the rows in the order of PHYSICS.md §3.
// ================================================================================================
const LawRow kLaws[] = {
    {"linear-dashpot", "linear spring-dashpot (Cundall-Strack), contact ends at overlap 0",
     laws::MakeLinearDashpot},
    {"linear-dashpot-force-zero",
     "linear spring-dashpot, contact ends when the force reaches 0 (ball detaches early)",
     laws::MakeLinearDashpotForceZero},
    {"walton-braun", "seed 002's law: (1+gamma) k loading, (1-gamma) k unloading",
     laws::MakeWaltonBraun},
    {"walton-braun-hysteretic", "Walton-Braun hysteresis: load k1, unload k2 with plastic offset",
     laws::MakeWaltonBraunHysteretic},
    {"hertz-tsuji", "Hertz + viscous damping d^1/4 (Tsuji 1992), speed-independent e",
     laws::MakeHertzTsuji},
    {"hertz-viscoelastic", "viscoelastic Hertz (Brilliantov 1996 / Kuwabara-Kono), e falls with v",
     laws::MakeHertzViscoelastic},
    {"hunt-crossley", "Hunt-Crossley k d^n (1 + alpha d'), alpha given", laws::MakeHuntCrossley},
    {"hunt-crossley-hc", "Hunt-Crossley with alpha = 3(1-e)/(2 v0) from target e, v0",
     laws::MakeHuntCrossleyHC},
    {"hunt-crossley-ln", "Hunt-Crossley with Lankarani-Nikravesh alpha = 3(1-e^2)/(4 v0)",
     laws::MakeHuntCrossleyLN},
    {"hunt-crossley-flores", "Hunt-Crossley with Flores alpha = 8(1-e)/(5 e v0)",
     laws::MakeHuntCrossleyFlores},
    {"jiang-liu", "Jiang-Liu thermodynamic law (seed 000), relaxation energy w_r, normal only",
     laws::MakeJiangLiu},
    {"expression", "user-defined force from a muParser expression in d, v and named parameters",
     laws::MakeExpression},
};

const LawRow* FindRow(const std::string& name) {
  for (const LawRow& row : kLaws) {
    if (name == row.name) return &row;
  }
  return nullptr;
}

std::string KnownNames() {
  std::string out;
  for (const LawRow& row : kLaws) {
    if (!out.empty()) out += ", ";
    out += row.name;
  }
  return out;
}

std::string Num(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

}  // namespace

std::vector<LawInfo> RegisteredLaws() {
  std::vector<LawInfo> out;
  for (const LawRow& row : kLaws) out.push_back({row.name, row.summary});
  return out;
}

ContactBody BodyFromScene(const Scene& scene) {
  // A ball on a rigid wall: m* = m, R* = R (PHYSICS.md §3, mass conventions). The surface
  // compliance effect (plate on a spring) is handled by the simulator, not by the law's body.
  return ContactBody::BallOnRigidWall(scene.ball.Mass(), scene.ball.Radius());
}

std::unique_ptr<ContactLaw> CreateLaw(const LawSpec& spec, const Scene& scene) {
  const LawRow* row = FindRow(spec.name);
  if (row == nullptr) {
    throw Error(ErrorCode::kBadParameter,
                "unknown contact law '" + spec.name + "' (known: " + KnownNames() + ")");
  }
  const ContactBody body = BodyFromScene(scene);
  std::unique_ptr<laws::LawBase> law = row->make(spec, scene);
  const std::vector<ParameterSpec>& specs = law->Parameters();
  std::vector<double> values(specs.size());
  for (size_t i = 0; i < specs.size(); ++i) values[i] = specs[i].default_value;
  for (const auto& [key, value] : spec.parameters) {
    const int index = law->ParameterIndex(key);
    if (index < 0) {
      std::string names;
      for (const ParameterSpec& s : specs) names += (names.empty() ? "" : ", ") + s.name;
      throw Error(ErrorCode::kBadParameter,
                  "law " + spec.name + ": unknown parameter '" + key + "' = " + Num(value) +
                      " (parameters: " + (names.empty() ? "none" : names) + ")");
    }
    if (!std::isfinite(value)) {
      throw Error(ErrorCode::kBadParameter, "law " + spec.name + ": parameter " + key + " = " +
                                                Num(value) + " is not a finite number");
    }
    values[static_cast<size_t>(index)] = value;
  }
  for (size_t i = 0; i < specs.size(); ++i) {
    if (std::isnan(values[i])) {
      // Only laws whose default depends on the scene use NaN defaults (e.g. Hertz k without
      // elastic constants); the spec's description says where the default comes from.
      throw Error(ErrorCode::kBadParameter, "law " + spec.name + ": parameter " + specs[i].name +
                                                " is required here (" + specs[i].description + ")");
    }
  }
  std::string error;
  if (!law->IsValid(values, body, &error)) throw Error(ErrorCode::kBadParameter, error);
  law->SetValues(std::move(values));
  return law;
}

}  // namespace bouncecal

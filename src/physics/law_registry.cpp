// The contact-law registry: one table, name -> law class and capabilities (law_registry.hpp).
#include "bouncecal/physics/law_registry.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "physics/laws/law_base.hpp"

namespace bouncecal {
namespace laws {
namespace {

// Closed forms a law provides (a column of its row; ContactLaw's closed-form methods).
enum ClosedForm : unsigned {
  kNone = 0,
  kRestitution = 1u << 0,   // Restitution(p, body, v)
  kContactTime = 1u << 1,   // ContactTime(p, body, v)
  kSolveContact = 1u << 2,  // SolveContact(p, body, v): the simulator skips integration
  kInverse = 1u << 3,       // DampingForRestitution(p, body, e, v)
  kGradient = 1u << 4,      // RestitutionGradient(p, body, v, ...)
  kAllLinear = kRestitution | kContactTime | kSolveContact | kInverse | kGradient,
  kMasterCurve = kRestitution | kContactTime | kInverse | kGradient,
};

struct LawRow {
  const char* name;     // registry name, as typed in scene files and on the command line
  const char* summary;  // one line for `bouncecal laws`
  const char* formula;  // one line
  const char* source;   // paper + equation
  ContactEnd end_rule;
  bool needs_expression;  // defined by LawSpec::expression
  unsigned closed_forms;  // ClosedForm bits
  ExportMapping export_mapping;
  const char* export_note;  // kConstantLinear: why no native law ("{target}": the simulator)
  LawFactory make;
};

constexpr ContactEnd kOverlap = ContactEnd::kOverlapZero;
constexpr ContactEnd kForce = ContactEnd::kForceZero;
constexpr ExportMapping kToLinear = ExportMapping::kLinearDashpot;
constexpr ExportMapping kToConstantLinear = ExportMapping::kConstantLinear;
constexpr ExportMapping kToTsuji = ExportMapping::kHertzTsuji;
constexpr ExportMapping kToViscoelastic = ExportMapping::kHertzViscoelastic;
constexpr ExportMapping kToClosestHertz = ExportMapping::kClosestHertz;

}  // namespace

// ================================================================================================
// THE TABLE. To add a contact law:
//   1. write src/physics/laws/<name>.cpp: one class L : LawImpl<L> following the recipe at the
//      top of laws/law_impl.hpp (parameter specs in L::Create; Constants, Prepare, Force, and
//      where they apply StateRate/Switch, templated on the scalar type; ElasticEnergy; the
//      closed forms it has), ending with
//        template std::unique_ptr<LawBase> MakeLaw<L>(const LawSpec&, const Scene&);
//   2. add ONE row below: name, summary, formula, source, end rule, needs an expression,
//      closed forms, export mapping (and its note), MakeLaw<class L> (the `class L` there
//      declares the class; nothing else anywhere names the law).
// Tests pick the law up from the table (the oracle comparison, the derivative checks, the
// registry consistency test: the closed forms the row lists must exist). Parameters are set by
// name by CreateLaw (unknown names, NaN, out-of-bounds values are rejected there), so a law only
// declares them. Keep the rows in the order of docs/physics.md §3.
// ================================================================================================
// (At namespace laws scope, not in an unnamed namespace: `MakeLaw<class L>` declares L in the
// enclosing namespace, where the law's file defines it.)
static const LawRow kLaws[] = {
    {"linear-dashpot", "linear spring-dashpot (Cundall-Strack), contact ends at overlap 0",
     "F = k d + c d'", "Cundall & Strack 1979; closed form: damped oscillator (docs/physics.md §3)",
     kOverlap, false, kAllLinear, kToLinear, "", MakeLaw<class LinearDashpot>},
    {"linear-dashpot-force-zero",
     "linear spring-dashpot, contact ends when the force reaches 0 (ball detaches early)",
     "F = k d + c d'", "Cundall & Strack 1979; closed form: damped oscillator (docs/physics.md §3)",
     kForce, false, kAllLinear, kToLinear, "", MakeLaw<class LinearDashpot>},
    {"walton-braun", "seed 002's law: (1+gamma) k loading, (1-gamma) k unloading",
     "F = (1 + gamma) k d if d' > 0, (1 - gamma) k d otherwise",
     "Zhong et al., Acta Phys. Sin. 58 (2009), eqs. 3-4 and 23 (seed 002)", kOverlap, false,
     kAllLinear, kToConstantLinear,
     "the seed law's (1 +- gamma) k branches are not native in {target}",
     MakeLaw<class WaltonBraun>},
    {"walton-braun-hysteretic", "Walton-Braun hysteresis: load k1, unload k2 with plastic offset",
     "F = k1 d loading, k2 (d - d0) unloading, d0 = dmax (1 - k1/k2)",
     "Walton & Braun, J. Rheol. 30 (1986) 949; e^2 = k1/k2 (docs/physics.md §3)", kForce, false,
     kAllLinear, kToConstantLinear,
     "Walton-Braun hysteresis with constant k2 is not native in {target} (LIGGGHTS "
     "hooke/hysteresis lets k2 grow with the overlap)",
     MakeLaw<class WaltonBraunHysteretic>},
    {"hertz-tsuji", "Hertz + viscous damping d^1/4 (Tsuji 1992), speed-independent e",
     "F = k d^1.5 + alpha(e) sqrt(m* k) d^0.25 d'",
     "Tsuji et al., Powder Technol. 71 (1992) 239, eq. 12; alpha(e) exact (master curve)", kOverlap,
     false, kMasterCurve, kToTsuji, "", MakeLaw<class HertzTsuji>},
    {"hertz-viscoelastic", "viscoelastic Hertz (Brilliantov 1996 / Kuwabara-Kono), e falls with v",
     "F = k (d^1.5 + 1.5 A d^0.5 d')",
     "Brilliantov et al., PRE 53 (1996) 5382; Ramirez et al., PRE 60 (1999) 4465", kOverlap, false,
     kMasterCurve, kToViscoelastic, "", MakeLaw<class HertzViscoelastic>},
    {"hunt-crossley", "Hunt-Crossley k d^n (1 + alpha d'), alpha given", "F = k d^n (1 + alpha d')",
     "Hunt & Crossley, J. Appl. Mech. 42 (1975) 440", kOverlap, false, kNone, kToClosestHertz, "",
     MakeLaw<class HuntCrossley>},
    {"hunt-crossley-hc", "Hunt-Crossley with alpha = 3(1-e)/(2 v0) from target e, v0",
     "F = k d^n (1 + alpha d'), alpha = 3(1-e)/(2 v0)",
     "Hunt & Crossley, J. Appl. Mech. 42 (1975) 440", kOverlap, false, kNone, kToClosestHertz, "",
     MakeLaw<class HuntCrossleyHC>},
    {"hunt-crossley-ln", "Hunt-Crossley with Lankarani-Nikravesh alpha = 3(1-e^2)/(4 v0)",
     "F = k d^n (1 + alpha d'), alpha = 3(1-e^2)/(4 v0)",
     "Lankarani & Nikravesh, J. Mech. Des. 112 (1990) 369", kOverlap, false, kNone, kToClosestHertz,
     "", MakeLaw<class HuntCrossleyLN>},
    {"hunt-crossley-flores", "Hunt-Crossley with Flores alpha = 8(1-e)/(5 e v0)",
     "F = k d^n (1 + alpha d'), alpha = 8(1-e)/(5 e v0)",
     "Flores et al., Mech. Mach. Theory 46 (2011) 1359", kOverlap, false, kNone, kToClosestHertz,
     "", MakeLaw<class HuntCrossleyFlores>},
    {"jiang-liu", "Jiang-Liu thermodynamic law (seed 000), relaxation energy w_r, normal only",
     "F = k d^1.5 + a w_r^0.25 Theta(d/D) d', dw_r/dt = a w_r^0.25 Theta d'^2 - w_r/tau",
     "Jiang & Liu, Acta Phys. Sin. 67 (2018) 044502, eqs. 28-33, 37-39 (seed 000)", kOverlap, false,
     kNone, kToClosestHertz, "", MakeLaw<class JiangLiu>},
    {"expression", "user-defined force from a muParser expression in d, v and named parameters",
     "F = user expression in d, v and named parameters", "user-defined (muParser expression)",
     kOverlap, true, kNone, kToClosestHertz, "", MakeLaw<class Expression>},
};

}  // namespace laws

namespace {

using laws::kLaws;
using laws::LawRow;

LawInfo InfoOf(const LawRow& row) {
  LawInfo info;
  info.name = row.name;
  info.summary = row.summary;
  info.formula = row.formula;
  info.source = row.source;
  info.end_rule = row.end_rule;
  info.needs_expression = row.needs_expression;
  info.export_mapping = row.export_mapping;
  info.export_note = row.export_note;
  const std::pair<unsigned, const char*> forms[] = {
      {laws::kRestitution, "restitution"},       {laws::kContactTime, "contact_time"},
      {laws::kSolveContact, "solve_contact"},    {laws::kInverse, "damping_for_restitution"},
      {laws::kGradient, "restitution_gradient"},
  };
  for (const auto& [bit, name] : forms) {
    if (row.closed_forms & bit) info.closed_forms.push_back(name);
  }
  return info;
}

const std::vector<LawInfo>& Infos() {
  static const std::vector<LawInfo> infos = [] {
    std::vector<LawInfo> out;
    for (const LawRow& row : kLaws) out.push_back(InfoOf(row));
    return out;
  }();
  return infos;
}

std::string KnownNames() {
  std::string out;
  for (const LawRow& row : kLaws) {
    if (!out.empty()) out += ", ";
    out += row.name;
  }
  return out;
}

}  // namespace

bool LawInfo::HasClosedForm(const std::string& form) const {
  return std::find(closed_forms.begin(), closed_forms.end(), form) != closed_forms.end();
}

std::vector<LawInfo> RegisteredLaws() { return Infos(); }

const LawInfo* FindLaw(const std::string& name) {
  for (const LawInfo& info : Infos()) {
    if (info.name == name) return &info;
  }
  return nullptr;
}

std::string ExpressionLawName() {
  for (const LawInfo& info : Infos()) {
    if (info.needs_expression) return info.name;
  }
  return "";
}

ContactBody BodyFromScene(const Scene& scene) {
  // A ball on a rigid wall: m* = m, R* = R (docs/physics.md §3, mass conventions). The surface
  // compliance effect (plate on a spring) is handled by the simulator, not by the law's body.
  return ContactBody::BallOnRigidWall(scene.ball.Mass(), scene.ball.Radius());
}

std::unique_ptr<ContactLaw> CreateLaw(const LawSpec& spec, const Scene& scene) {
  const LawRow* row = nullptr;
  size_t index = 0;
  for (size_t i = 0; i < std::size(kLaws); ++i) {
    if (spec.name == kLaws[i].name) {
      row = &kLaws[i];
      index = i;
    }
  }
  if (row == nullptr) {
    throw Error(ErrorCode::kBadParameter, "unknown contact law '" + Abbreviate(spec.name) +
                                              "' (known: " + KnownNames() + ")");
  }
  const ContactBody body = BodyFromScene(scene);
  std::unique_ptr<laws::LawBase> law = row->make(spec, scene);
  law->SetRow(Infos()[index]);
  const std::vector<ParameterSpec>& specs = law->Parameters();
  std::vector<double> values(specs.size());
  for (size_t i = 0; i < specs.size(); ++i) values[i] = specs[i].default_value;
  for (const auto& [key, value] : spec.parameters) {
    const int at = law->ParameterIndex(key);
    if (at < 0) {
      std::string names;
      for (const ParameterSpec& s : specs) names += (names.empty() ? "" : ", ") + s.name;
      throw Error(ErrorCode::kBadParameter,
                  "law " + spec.name + ": unknown parameter '" + Abbreviate(key) +
                      "' = " + FormatGeneral(value, 10) +
                      " (parameters: " + (names.empty() ? "none" : names) + ")");
    }
    if (!std::isfinite(value)) {
      throw Error(ErrorCode::kBadParameter, "law " + spec.name + ": parameter " + key + " = " +
                                                FormatGeneral(value, 10) +
                                                " is not a finite number");
    }
    values[static_cast<size_t>(at)] = value;
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

LawSpec ExampleLawSpec(const std::string& name) {
  LawSpec spec;
  spec.name = name;
  const LawInfo* row = FindLaw(name);
  if (row != nullptr && row->needs_expression) {
    spec.expression = "k * d^1.5 * (1 + alpha * v)";
    spec.parameters = {{"k", 1e10}, {"alpha", 0.3}};
  }
  return spec;
}

}  // namespace bouncecal

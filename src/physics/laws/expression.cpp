// User-defined contact law: the normal force is a muParser expression (muParser 2.3, Debian
// libmuparser) in
//   d  overlap delta (m),  v  overlap rate delta' (m/s, > 0 while loading),
// and the named parameters of the LawSpec (any finite values), e.g.
//   expression = "k * d^1.5 * (1 + alpha * v)",  parameters = {k = 1e10, alpha = 0.3}.
// Parameters named "k" or starting with "k_" are stiffnesses (held by the fitter); all others
// are damping parameters (fitted). The contact ends at d = 0. The force is whatever the
// expression says (it may turn attractive). Elastic energy = the work of the rate-independent
// part, integral_0^d F(x, 0) dx (16-point Gauss-Legendre in u = sqrt(x/d)). No closed forms.
// Each law instance owns its parser (muParser is not thread-safe): one instance per thread,
// as for every law (contact_law.hpp); its dynamics share that parser.
// muParser evaluates doubles only, so this is the one registered law whose force is not
// templated on the scalar type: its dynamics are PointwiseDynamics (pointwise_law.hpp), whose
// derivatives (forward sensitivities) are central differences of the expression.
#include <muParser.h>

#include <cmath>
#include <limits>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/pointwise_law.hpp"
#include "physics/laws/law_impl.hpp"

namespace bouncecal::laws {
namespace {

// 16-point Gauss-Legendre nodes and weights on [-1, 1] (Abramowitz & Stegun, table 25.4).
constexpr double kGaussX[8] = {0.0950125098376374, 0.2816035507792589, 0.4580167776572274,
                               0.6178762444026438, 0.7554044083550030, 0.8656312023878318,
                               0.9445750230732326, 0.9894009349916499};
constexpr double kGaussW[8] = {0.1894506104550685, 0.1826034150449236, 0.1691565193950025,
                               0.1495959888165767, 0.1246289712555339, 0.0951585116824928,
                               0.0622535239386479, 0.0271524594117541};

}  // namespace

class Expression final : public LawBase {
 public:
  static std::unique_ptr<LawBase> Create(const LawSpec& spec, const Scene&) {
    return std::make_unique<Expression>(spec);
  }
  explicit Expression(const LawSpec& spec) : expression_(spec.expression) {
    if (expression_.empty()) {
      throw Error(ErrorCode::kBadParameter,
                  "law expression: no force expression given (law.expression, e.g. "
                  "\"k * d^1.5 * (1 + alpha * v)\")");
    }
    values_.reserve(spec.parameters.size());
    vars_.assign(spec.parameters.size(), 0.0);  // stable addresses for DefineVar
    try {
      parser_.DefineVar("d", &d_);
      parser_.DefineVar("v", &v_);
      size_t i = 0;
      for (const auto& [name, value] : spec.parameters) {
        if (name == "d" || name == "v") {
          throw Error(ErrorCode::kBadParameter, "law expression: parameter name '" + name +
                                                    "' is reserved (d = overlap, v = rate)");
        }
        const bool stiffness = name == "k" || name.rfind("k_", 0) == 0;
        specs_.push_back(Spec(name, "user", "user parameter of the expression",
                              std::numeric_limits<double>::lowest(),
                              std::numeric_limits<double>::max(), value, !stiffness));
        parser_.DefineVar(name, &vars_[i]);
        vars_[i] = value;
        ++i;
      }
      parser_.SetExpr(expression_);
      d_ = 1e-6;
      v_ = 0.0;
      parser_.Eval();  // forces the parse: syntax errors and unknown names surface here
    } catch (const mu::Parser::exception_type& e) {
      throw Error(ErrorCode::kBadParameter,
                  "law expression: cannot use \"" + Abbreviate(expression_) + "\": " + e.GetMsg() +
                      (e.GetPos() >= 0 ? " (at position " + std::to_string(e.GetPos()) + ")"
                                       : std::string()));
    }
  }
  Expression(const Expression&) = delete;
  Expression& operator=(const Expression&) = delete;

  std::string Formula() const override { return "F = " + expression_; }
  int StateSize() const override { return 0; }
  std::unique_ptr<ContactDynamics> Dynamics(std::span<const double> p,
                                            const ContactBody&) const override;

  double Force(std::span<const double> p, double delta_m, double delta_dot_m_s) const {
    if (delta_m <= 0.0) return 0.0;
    return Eval(p, delta_m, delta_dot_m_s);
  }
  double ElasticEnergy(std::span<const double> p, double delta_m) const {
    if (delta_m <= 0.0) return 0.0;
    // x = d u^2 makes Hertz-type integrands (x^1.5 -> 2 d^2.5 u^4) polynomial in u.
    double sum = 0.0;
    for (int i = 0; i < 8; ++i) {
      for (double u : {0.5 * (1.0 - kGaussX[i]), 0.5 * (1.0 + kGaussX[i])}) {
        sum += kGaussW[i] * 0.5 * Eval(p, delta_m * u * u, 0.0) * 2.0 * delta_m * u;
      }
    }
    return sum;
  }

 private:
  double Eval(std::span<const double> p, double d, double v) const {
    for (size_t i = 0; i < vars_.size(); ++i) vars_[i] = p[i];
    d_ = d;
    v_ = v;
    try {
      return parser_.Eval();
    } catch (const mu::Parser::exception_type&) {
      return std::numeric_limits<double>::quiet_NaN();  // the simulator rejects NaN forces
    }
  }

  std::string expression_;
  mutable mu::Parser parser_;
  mutable double d_ = 0.0, v_ = 0.0;
  mutable std::vector<double> vars_;
};

std::unique_ptr<ContactDynamics> Expression::Dynamics(std::span<const double> p,
                                                      const ContactBody&) const {
  // The parser at fixed p; derivatives by central differences (pointwise_law.hpp).
  return std::make_unique<PointwiseDynamics>(
      [this](std::span<const double> q, double d, double v) { return Force(q, d, v); },
      [this](std::span<const double> q, double d) { return ElasticEnergy(q, d); }, EndRule(), p);
}

template std::unique_ptr<LawBase> MakeLaw<Expression>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws

#include "physics/laws/unit_contact.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>

#include <boost/numeric/odeint.hpp>

namespace bouncecal::laws {

UnitContact IntegrateUnitContact(const std::function<double(double, double)>& force,
                                 bool force_zero_end, double rel_tol, double max_time) {
  namespace odeint = boost::numeric::odeint;
  using State = std::array<double, 2>;
  auto rhs = [&](const State& x, State& dxdt, double) {
    dxdt[0] = x[1];
    dxdt[1] = -force(x[0], x[1]);
  };
  auto ended = [&](const State& x) {
    if (x[1] >= 0.0) return false;
    return x[0] <= 0.0 || (force_zero_end && force(x[0], x[1]) <= 0.0);
  };
  // Relative control only (absolute 1e-300): both components are O(1) by construction.
  auto dense = odeint::make_dense_output(1e-300, rel_tol, odeint::runge_kutta_dopri5<State>());
  dense.initialize(State{0.0, 1.0}, 0.0, 1e-6);
  State mid{};
  auto bisect = [&](double t0, double t1, auto pred) {
    for (int i = 0; i < 200 && t1 - t0 > 1e-15 * t1; ++i) {
      const double tm = 0.5 * (t0 + t1);
      dense.calc_state(tm, mid);
      (pred(mid) ? t1 : t0) = tm;
    }
    return t1;
  };
  UnitContact out;
  while (true) {
    const double t0 = dense.current_time();
    const State a = dense.current_state();
    dense.do_step(rhs);
    const double t1 = dense.current_time();
    const State b = dense.current_state();
    if (a[1] > 0.0 && b[1] <= 0.0) {
      dense.calc_state(bisect(t0, t1, [](const State& s) { return s[1] <= 0.0; }), mid);
      out.peak_overlap = mid[0];
    }
    if (ended(b)) {
      out.contact_time = bisect(t0, t1, ended);
      dense.calc_state(out.contact_time, mid);
      out.restitution = -mid[1];
      return out;
    }
    if (t1 > max_time || !std::isfinite(b[0])) {
      out.stuck = true;
      out.contact_time = t1;
      return out;
    }
  }
}

HermiteTable::HermiteTable(std::vector<double> x, std::vector<double> y, std::vector<double> dy)
    : x_(std::move(x)), y_(std::move(y)), dy_(std::move(dy)) {
  assert(x_.size() >= 2 && x_.size() == y_.size() && x_.size() == dy_.size());
  assert(std::is_sorted(x_.begin(), x_.end()));
}

size_t HermiteTable::Cell(double x) const {
  const auto it = std::upper_bound(x_.begin(), x_.end(), x);
  const size_t i = static_cast<size_t>(std::max<std::ptrdiff_t>(it - x_.begin(), 1)) - 1;
  return std::min(i, x_.size() - 2);
}

double HermiteTable::operator()(double x) const {
  x = std::clamp(x, x_.front(), x_.back());
  const size_t i = Cell(x);
  const double h = x_[i + 1] - x_[i];
  const double s = (x - x_[i]) / h;
  const double s2 = s * s, s3 = s2 * s;
  return (2 * s3 - 3 * s2 + 1) * y_[i] + (s3 - 2 * s2 + s) * h * dy_[i] +
         (-2 * s3 + 3 * s2) * y_[i + 1] + (s3 - s2) * h * dy_[i + 1];
}

double HermiteTable::Derivative(double x) const {
  x = std::clamp(x, x_.front(), x_.back());
  const size_t i = Cell(x);
  const double h = x_[i + 1] - x_[i];
  const double s = (x - x_[i]) / h;
  const double s2 = s * s;
  return ((6 * s2 - 6 * s) * y_[i] + (3 * s2 - 4 * s + 1) * h * dy_[i] +
          (-6 * s2 + 6 * s) * y_[i + 1] + (3 * s2 - 2 * s) * h * dy_[i + 1]) /
         h;
}

}  // namespace bouncecal::laws

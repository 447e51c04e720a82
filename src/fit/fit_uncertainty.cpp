// Calibration stages 3b-4: the best of several starts, identifiability, parameter covariance and
// the e(v) band (calibrate_stages.hpp).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "fit/calibrate_stages.hpp"

namespace bouncecal::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Singular values below this fraction of the largest span the numerical null space
// (sqrt of double precision's ~1e-16 relative noise in J^T J).
constexpr double kNullSpaceRatio = 1e-8;

std::vector<int> ActiveOf(const Solution& s) {
  std::vector<int> a;
  for (size_t j = 0; j < s.held.size(); ++j) {
    if (!s.held[j]) a.push_back(static_cast<int>(j));
  }
  return a;
}

// Whitened Jacobian of the solution (C at its sigma_s), law columns in relative units.
Eigen::MatrixXd WhitenedRelative(const FitProblem& fp, const Solution& s) {
  const ScatterProblem sp(s.residuals, s.jacobian, s.timing_cov, s.design);
  Eigen::LLT<Eigen::MatrixXd> llt(sp.Covariance(s.scatter.sigma));
  Eigen::MatrixXd jw = llt.matrixL().solve(s.jacobian);
  const std::vector<int> active = ActiveOf(s);
  for (size_t j = 0; j < active.size(); ++j) {
    const size_t a = static_cast<size_t>(active[j]);
    const size_t i = static_cast<size_t>(fp.setup.free[a]);
    // d r / d(x / max(|x|, typical)): a unit sigma is a 100 % relative sigma.
    jw.col(static_cast<Eigen::Index>(j)) *=
        std::max(std::abs(s.p[i]), fp.setup.typical[i]) / fp.setup.scale[a];
  }
  return jw;
}

// Columns that load on the numerical null space, or whose relative sigma exceeds the threshold.
std::vector<bool> NullOrLoose(const Eigen::MatrixXd& js, double rel_sigma_max,
                              std::vector<double>* rel_sigma, std::vector<bool>* in_null) {
  const Eigen::Index n = js.cols();
  std::vector<bool> bad(static_cast<size_t>(n), false);
  in_null->assign(static_cast<size_t>(n), false);
  rel_sigma->assign(static_cast<size_t>(n), std::numeric_limits<double>::infinity());
  if (n == 0) return bad;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(js, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  const double smax = sv.size() ? sv(0) : 0.0;
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::VectorXd v = svd.matrixV().col(i);
    if (i >= sv.size() || !(smax > 0.0) || sv(i) <= kNullSpaceRatio * smax) {
      for (Eigen::Index j = 0; j < n; ++j) {
        if (std::abs(v(j)) > 0.1)
          (*in_null)[static_cast<size_t>(j)] = bad[static_cast<size_t>(j)] = true;
      }
    } else {
      cov += v * v.transpose() / (sv(i) * sv(i));
    }
  }
  for (Eigen::Index j = 0; j < n; ++j) {
    if (bad[static_cast<size_t>(j)]) continue;
    (*rel_sigma)[static_cast<size_t>(j)] = std::sqrt(std::max(cov(j, j), 0.0));
    if ((*rel_sigma)[static_cast<size_t>(j)] > rel_sigma_max) bad[static_cast<size_t>(j)] = true;
  }
  return bad;
}

// d e(u_k) / d x_i at every data point (restitution model column of a law parameter).
Eigen::VectorXd ModelColumn(const FitProblem& fp, const std::vector<double>& p, size_t i,
                            std::atomic<long>* sims) {
  const LawSetup& s = fp.setup;
  const ParameterSpec& sp = s.specs()[i];
  const double rel = s.has_closed_e ? 1e-6 : RelativeStep(fp.options.rel_tolerance);
  const double x = p[i], h = rel * std::max(std::abs(x), s.typical[i]);
  const double hi = std::min(x + h, sp.upper), lo = std::max(x - h, sp.lower);
  Eigen::VectorXd col = Eigen::VectorXd::Zero(fp.data.size());
  if (!(hi > lo)) return col;
  std::vector<double> qh = p, ql = p;
  qh[i] = hi;
  ql[i] = lo;
  std::string err;
  if (!s.law->IsValid(qh, s.body, &err) || !s.law->IsValid(ql, s.body, &err)) return col;
  try {
    ForEachSpeed(fp, static_cast<std::size_t>(fp.data.size()), 2, [&](std::size_t k) {
      const double u = fp.data.points[k].u_m_s;
      col(static_cast<Eigen::Index>(k)) = (ModelRestitution(s, qh, u, fp.g, fp.sim, sims) -
                                           ModelRestitution(s, ql, u, fp.g, fp.sim, sims)) /
                                          (hi - lo);
    });
  } catch (const Error&) {
    col.setZero();
  }
  return col;
}

}  // namespace

Solution SolveFromStarts(const FitProblem& fp, const std::vector<std::vector<double>>& starts,
                         const std::vector<bool>& held, StartsReport* report,
                         std::atomic<long>* sims) {
  // The restitution fit from every start at the screen's sigma_s, then the best alternated.
  std::vector<Solution> trials;
  for (const auto& st : starts) {
    trials.push_back(
        SolveRestitution(fp, st, held, fp.scatter_start, false, sims, &starts.front()));
  }
  auto best_of = [](const std::vector<Solution>& v) {
    int b = -1;
    for (size_t i = 0; i < v.size(); ++i) {
      if (v[i].ok && (b < 0 || v[i].cost < v[static_cast<size_t>(b)].cost)) b = static_cast<int>(i);
    }
    return b;
  };
  int b = best_of(trials);
  if (b < 0) return trials.front();
  Solution best =
      SolveRestitution(fp, trials[static_cast<size_t>(b)].p, held, fp.scatter_start, true, sims);
  if (fp.options.strategy == FitStrategy::kTrajectory && best.ok) {
    // The trajectory from the restitution optimum and the same starts, at its sigma_s.
    std::vector<std::vector<double>> tstarts = {best.p};
    for (const auto& st : starts) tstarts.push_back(st);
    tstarts.resize(std::min<size_t>(tstarts.size(), static_cast<size_t>(fp.options.max_starts)));
    std::vector<Solution> ttrials;
    for (const auto& st : tstarts)
      ttrials.push_back(SolveTrajectory(fp, st, held, best.scatter.sigma, sims));
    const int tb = best_of(ttrials);
    if (tb < 0) return ttrials.front();
    Solution t = ttrials[static_cast<size_t>(tb)];
    t.iterations = best.iterations;
    for (const auto& tr : ttrials) t.iterations += tr.iterations;
    trials = std::move(ttrials);
    b = tb;
    best = std::move(t);
  }
  if (report && best.ok) {
    // Starts agree when they end within one sigma of the best; they disagree when one ends
    // more than two sigmas away with a fit as good (chi2 within 4, i.e. 2 sigma).
    report->tried = static_cast<int>(trials.size());
    report->reached_best = 0;
    report->disagree = false;
    const std::vector<int> active = ActiveOf(best);
    const Solution& ref = trials[static_cast<size_t>(b)];
    const double best_cost = ref.cost;
    for (const Solution& tr : trials) {
      if (!tr.ok) continue;
      double d = 0.0;
      for (size_t j = 0; j < active.size(); ++j) {
        const size_t a = static_cast<size_t>(active[j]);
        const size_t i = static_cast<size_t>(fp.setup.free[a]);
        const double sig = std::sqrt(std::max(best.scatter.covariance(static_cast<Eigen::Index>(j),
                                                                      static_cast<Eigen::Index>(j)),
                                              0.0)) *
                           fp.setup.scale[a];
        if (sig > 0.0) d = std::max(d, std::abs(tr.p[i] - ref.p[i]) / sig);
      }
      if (d <= 1.0) ++report->reached_best;
      if (d > 2.0 && tr.cost - best_cost <= 2.0) {
        report->disagree = true;
        std::ostringstream os;
        os << "a start ends " << FormatGeneral(d, 2) << " sigma away with chi2 within "
           << FormatGeneral(2.0 * (tr.cost - best_cost), 2) << " of the best (";
        for (size_t j = 0; j < active.size(); ++j) {
          const size_t i = static_cast<size_t>(fp.setup.free[static_cast<size_t>(active[j])]);
          os << (j ? ", " : "") << fp.setup.specs()[i].name << " " << FormatGeneral(tr.p[i], 4)
             << " vs " << FormatGeneral(ref.p[i], 4);
        }
        os << ")";
        report->note = os.str();
      }
    }
  }
  return best;
}

std::vector<bool> FindUndetermined(const Solution& s, const FitProblem& fp,
                                   std::vector<std::string>* why) {
  std::vector<bool> out(fp.setup.free.size(), false);
  why->assign(fp.setup.free.size(), "");
  if (!s.ok) return out;
  const Eigen::MatrixXd js_all = WhitenedRelative(fp, s);
  const std::vector<int> active = ActiveOf(s);
  // Columns still considered; a degenerate combination (k and A enter a viscoelastic e only as
  // A k^(2/5)) is resolved by declaring the freed non-damping parameter undetermined first and
  // testing the rest again, so the damping keeps its value and sigma.
  std::vector<size_t> cols(active.size());
  for (size_t j = 0; j < cols.size(); ++j) cols[j] = j;
  while (!cols.empty()) {
    Eigen::MatrixXd js(js_all.rows(), static_cast<Eigen::Index>(cols.size()));
    for (size_t c = 0; c < cols.size(); ++c)
      js.col(static_cast<Eigen::Index>(c)) = js_all.col(static_cast<Eigen::Index>(cols[c]));
    std::vector<double> rel;
    std::vector<bool> null;
    const auto bad = NullOrLoose(js, fp.options.undetermined_relative_sigma, &rel, &null);
    std::vector<size_t> drop;
    for (size_t c = 0; c < cols.size(); ++c) {
      const size_t a = static_cast<size_t>(active[cols[c]]);
      if (bad[c] && !fp.setup.specs()[static_cast<size_t>(fp.setup.free[a])].damping)
        drop.push_back(c);
    }
    const bool only_freed = !drop.empty();
    if (!only_freed) {
      for (size_t c = 0; c < cols.size(); ++c) {
        if (bad[c]) drop.push_back(c);
      }
    }
    for (size_t c : drop) {
      const size_t a = static_cast<size_t>(active[cols[c]]);
      const std::string name = fp.setup.specs()[static_cast<size_t>(fp.setup.free[a])].name;
      out[a] = true;
      (*why)[a] = null[c]
                      ? name +
                            ": the fitted quantities do not change with it (or only "
                            "together with another parameter) at the measured speeds"
                      : name + ": its relative sigma " + FormatGeneral(rel[c], 2) + " exceeds " +
                            FormatGeneral(fp.options.undetermined_relative_sigma, 2);
    }
    if (!only_freed || drop.empty()) break;
    std::vector<size_t> rest;
    for (size_t c = 0; c < cols.size(); ++c) {
      if (std::find(drop.begin(), drop.end(), c) == drop.end()) rest.push_back(cols[c]);
    }
    cols = rest;
  }
  return out;
}

Uncertainty EstimateUncertainty(const FitProblem& fp, const Solution& s, std::atomic<long>* sims) {
  Uncertainty u;
  const LawSetup& su = fp.setup;
  const size_t nall = su.start.size();
  u.sigma.assign(nall, kNaN);
  u.held_determinable.assign(nall, false);
  u.undetermined = s.held;
  u.undetermined_why.assign(su.free.size(), "");
  if (!s.ok) return u;
  const std::vector<int> active = ActiveOf(s);
  const Eigen::Index na = static_cast<Eigen::Index>(active.size());
  u.covariance = Eigen::MatrixXd::Zero(na, na);
  for (Eigen::Index a = 0; a < na; ++a) {
    for (Eigen::Index b = 0; b < na; ++b) {
      u.covariance(a, b) = s.scatter.covariance(a, b) *
                           su.scale[static_cast<size_t>(active[static_cast<size_t>(a)])] *
                           su.scale[static_cast<size_t>(active[static_cast<size_t>(b)])];
    }
    u.sigma[static_cast<size_t>(su.free[static_cast<size_t>(active[static_cast<size_t>(a)])])] =
        std::sqrt(std::max(u.covariance(a, a), 0.0));
  }
  // Held law parameters: would the data determine each one if it alone were freed? Tested on
  // the restitution points (their sigmas and the scatter, correlations left out), for both
  // strategies.
  const int nd = fp.data.size();
  Eigen::VectorXd w(nd);
  for (int k = 0; k < nd; ++k) {
    w(k) = 1.0 / std::hypot(std::max(fp.data.points[static_cast<size_t>(k)].e_sigma, 1e-9),
                            s.scatter.sigma);
  }
  auto rel_column = [&](size_t i) {
    return Eigen::VectorXd(ModelColumn(fp, s.p, i, sims).cwiseProduct(w) *
                           std::max(std::abs(s.p[i]), su.typical[i]));
  };
  Eigen::MatrixXd cols(nd, na + 1);  // the active columns (the same for every held one), then it
  bool have_active = false;
  for (size_t i = 0; i < nall && nd > 0; ++i) {
    if (std::find(su.free.begin(), su.free.end(), static_cast<int>(i)) != su.free.end()) continue;
    for (Eigen::Index a = 0; a < na && !have_active; ++a) {
      cols.col(a) = rel_column(
          static_cast<size_t>(su.free[static_cast<size_t>(active[static_cast<size_t>(a)])]));
    }
    have_active = true;
    cols.col(na) = rel_column(i);
    std::vector<double> rel;
    std::vector<bool> null;
    const auto bad = NullOrLoose(cols, fp.options.undetermined_relative_sigma, &rel, &null);
    u.held_determinable[i] = !bad[static_cast<size_t>(na)];
  }
  // e(v) over the measured speeds, sigma from the parameter covariance.
  double lo = std::numeric_limits<double>::max(), hi = 0.0;
  if (fp.options.strategy == FitStrategy::kTrajectory) {
    for (const auto& v : s.v_in) {
      for (double x : v) {
        if (x > 0.0 && std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
      }
    }
  } else {
    for (const auto& p : fp.data.points) lo = std::min(lo, p.u_m_s), hi = std::max(hi, p.u_m_s);
  }
  if (!(hi > 0.0)) return u;
  u.v_min_m_s = lo;
  u.v_max_m_s = hi;
  const int n = fp.options.e_of_v_points;
  const double rel = su.has_closed_e ? 1e-6 : RelativeStep(fp.options.rel_tolerance);
  // The table's points at once (ForEachSpeed), kept in speed order.
  std::vector<std::optional<EOfVPoint>> points(static_cast<size_t>(n));
  ForEachSpeed(fp, static_cast<std::size_t>(n), 1 + 2 * static_cast<int>(na), [&](std::size_t q) {
    EOfVPoint pt;
    pt.v_m_s = lo * std::pow(hi / lo, static_cast<double>(q) / double(n - 1));
    try {
      pt.e = ModelRestitution(su, s.p, pt.v_m_s, fp.g, fp.sim, sims);
      Eigen::VectorXd grad(na);
      for (Eigen::Index a = 0; a < na; ++a) {
        const size_t i =
            static_cast<size_t>(su.free[static_cast<size_t>(active[static_cast<size_t>(a)])]);
        const ParameterSpec& sp = su.specs()[i];
        const double x = s.p[i], h = rel * std::max(std::abs(x), su.typical[i]);
        std::vector<double> qh = s.p, ql = s.p;
        qh[i] = std::min(x + h, sp.upper);
        ql[i] = std::max(x - h, sp.lower);
        grad(a) = qh[i] > ql[i] ? (ModelRestitution(su, qh, pt.v_m_s, fp.g, fp.sim, sims) -
                                   ModelRestitution(su, ql, pt.v_m_s, fp.g, fp.sim, sims)) /
                                      (qh[i] - ql[i])
                                : 0.0;
      }
      pt.sigma = std::sqrt(std::max(grad.dot(u.covariance * grad), 0.0));
    } catch (const Error&) {
      return;
    }
    if (std::isfinite(pt.e)) points[q] = pt;
  });
  for (const auto& pt : points)
    if (pt) u.e_of_v.push_back(*pt);
  return u;
}

}  // namespace bouncecal::calib

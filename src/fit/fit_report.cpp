// The human reports of a calibration and of a law comparison (calibrate.hpp).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "bouncecal/core/format.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "fit/text.hpp"

namespace bouncecal {
namespace {

using fit_text::Join;

std::string FormatResidual(double v, const std::string& unit) {
  if (!std::isfinite(v)) return "-";
  if (unit == "s") return FormatGeneral(v * 1e6, 4) + " us";
  return FormatGeneral(v, 4);
}

std::string ScatterText(const Calibration& c) {
  if (!std::isfinite(c.scatter_e)) return "-";
  if (c.scatter_at_zero) {
    return "0 (< " +
           (std::isfinite(c.scatter_e_sigma) ? FormatGeneral(c.scatter_e_sigma, 2) : "?") +
           ", 68 % upper limit)";
  }
  return FormatGeneral(c.scatter_e, 3) + " ± " + FormatGeneral(c.scatter_e_sigma, 2);
}

}  // namespace

std::string Calibration::BriefReport() const {
  std::ostringstream os;
  os << law << ":";
  bool first = true;
  for (const auto& p : parameters) {
    if (p.fixed) continue;
    os << (first ? " " : ", ") << p.name << " = " << FormatGeneral(p.value);
    if (std::isfinite(p.sigma)) os << " ± " << FormatGeneral(p.sigma, 2);
    if (!p.determined) os << " (undetermined)";
    first = false;
  }
  os << ", scatter " << (std::isfinite(scatter_e) ? FormatGeneral(scatter_e, 2) : "-")
     << ", chi2/dof " << (std::isfinite(chi2_dof) ? FormatGeneral(chi2_dof, 3) : "-") << " ("
     << FitOutcomeName(outcome) << ")";
  return os.str();
}

std::string Calibration::FullReport() const {
  std::ostringstream os;
  os << "law " << law << ", " << FitStrategyName(strategy) << " fit, "
     << DerivativeModeName(derivatives) << " derivatives ("
     << (analytic_jacobian ? "analytic Jacobian from the closed-form e(v)" : "central differences")
     << ")\n";
  os << "outcome: " << FitOutcomeName(outcome);
  if (outcome != FitOutcome::kConverged && !reason.empty()) os << " — " << reason;
  os << "\n";
  if (!hint.empty()) os << "next: " << hint << "\n";
  if (!message.empty()) os << "notes: " << message << "\n";
  os << "parameters:\n";
  size_t w = 4;
  for (const auto& p : parameters) w = std::max(w, p.name.size());
  for (const auto& p : parameters) {
    os << "  " << std::left << std::setw(static_cast<int>(w)) << p.name << " = " << std::setw(12)
       << FormatGeneral(p.value, 7);
    if (!p.fixed && std::isfinite(p.sigma)) {
      os << " ± " << std::setw(10) << FormatGeneral(p.sigma, 3);
    } else {
      os << "   " << std::setw(10) << "";
    }
    os << " " << std::setw(8) << p.unit << std::right;
    if (p.fixed) {
      os << "  held, not fitted"
         << (p.determined ? " (the data could fit it: free it with free_parameters)"
                          : " (the data cannot determine it)");
    } else if (p.determined) {
      os << "  fitted" << (p.at_bound ? ", at its bound" : "");
    } else {
      os << "  NOT determined by the data (held at its start value)";
    }
    os << "\n";
  }
  os << "scatter of e from bounce to bounce: " << ScatterText(*this) << "\n";
  if (!recordings.empty()) os << "recordings:\n";
  for (const auto& r : recordings) {
    os << "  " << r.name << ": " << r.impacts
       << (strategy == FitStrategy::kTrajectory ? " impacts" : " bounces");
    if (strategy == FitStrategy::kTrajectory) {
      os << " (" << r.simulated_impacts
         << " simulated), v0 = " << FormatGeneral(r.impact_speed_m_s);
      if (r.impact_speed_fixed) {
        os << " m/s (from the scene's drop)";
      } else {
        os << " ± " << FormatGeneral(r.impact_speed_sigma_m_s, 2) << " m/s";
      }
      os << ", t0 = " << std::fixed << std::setprecision(7) << r.time_origin_s << std::defaultfloat
         << " ± " << FormatGeneral(r.time_origin_sigma_s * 1e6, 2) << " us";
    }
    os << ", rms " << FormatResidual(r.rms_residual, residual_unit) << "\n";
  }
  os << "fit: " << num_residuals << " residuals, " << num_free << " free parameters + scatter, dof "
     << dof << ", chi2/dof " << (std::isfinite(chi2_dof) ? FormatGeneral(chi2_dof, 4) : "-")
     << " (timing + scatter), rms residual " << FormatResidual(rms_residual, residual_unit) << "\n";
  os << "     AIC " << FormatGeneral(aic) << ", BIC " << FormatGeneral(bic) << ", " << iterations
     << " iterations, " << simulations << " simulations\n";
  const auto det = Determined();
  const auto und = Undetermined();
  os << "determined by the sound: " << (det.empty() ? "(none)" : Join(det)) << "\n";
  os << "not determined by the sound: " << (und.empty() ? "(none)" : Join(und)) << "\n";
  if (!e_of_v.empty()) {
    os << "e(v) over the measured speeds " << FormatGeneral(v_min_m_s, 4) << " .. "
       << FormatGeneral(v_max_m_s, 4)
       << " m/s (the law's mean e; single bounces scatter by the scatter above):\n"
       << "    v (m/s)        e      sigma\n";
    for (const auto& pt : e_of_v) {
      os << "  " << std::setw(9) << FormatGeneral(pt.v_m_s, 4) << "  " << std::setw(9)
         << FormatGeneral(pt.e) << "  " << std::setw(9) << FormatGeneral(pt.sigma, 2) << "\n";
    }
  }
  return os.str();
}

std::string LawComparisonTable(const std::vector<LawComparisonRow>& rows,
                               const std::vector<double>& speeds_m_s) {
  std::ostringstream os;
  os << "| rank | law | outcome | fitted | scatter | chi2/dof | AIC | dAIC |";
  for (double v : speeds_m_s) os << " e(" << FormatGeneral(v, 3) << " m/s) |";
  os << "\n|---|---|---|---|---|---|---|---|";
  for (size_t i = 0; i < speeds_m_s.size(); ++i) os << "---|";
  os << "\n";
  int rank = 0;
  for (const auto& r : rows) {
    const Calibration& c = r.fit;
    os << "| " << (r.adequate ? std::to_string(++rank) : "-") << " | " << c.law << " | "
       << FitOutcomeName(c.outcome) << " | ";
    if (!r.adequate) {
      os << c.reason << " | | | | |";
      for (size_t i = 0; i < speeds_m_s.size(); ++i) os << " |";
      os << "\n";
      continue;
    }
    std::vector<std::string> fitted;
    for (const auto& p : c.parameters) {
      if (!p.fixed) fitted.push_back(p.name + "=" + FormatGeneral(p.value, 4));
    }
    os << Join(fitted, " ") << " | " << FormatGeneral(c.scatter_e, 2) << " | "
       << FormatGeneral(c.chi2_dof, 3) << " | " << FormatGeneral(c.aic) << " | "
       << FormatGeneral(r.delta_aic, 4) << " |";
    // e(v) by interpolating the fitted table (log-linear in v), clamped to its range.
    for (double v : speeds_m_s) {
      double e = std::nan("");
      const auto& t = c.e_of_v;
      if (!t.empty()) {
        if (v <= t.front().v_m_s) {
          e = t.front().e;
        } else if (v >= t.back().v_m_s) {
          e = t.back().e;
        } else {
          for (size_t i = 1; i < t.size(); ++i) {
            if (v <= t[i].v_m_s) {
              const double a = std::log(v / t[i - 1].v_m_s) / std::log(t[i].v_m_s / t[i - 1].v_m_s);
              e = t[i - 1].e + a * (t[i].e - t[i - 1].e);
              break;
            }
          }
        }
      }
      os << " " << (std::isfinite(e) ? FormatGeneral(e, 5) : std::string("-")) << " |";
    }
    os << "\n";
  }
  return os.str();
}

}  // namespace bouncecal

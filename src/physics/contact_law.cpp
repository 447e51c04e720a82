#include "bouncecal/physics/contact_law.hpp"

#include <cmath>
#include <sstream>

namespace bouncecal {

int ContactLaw::ParameterIndex(const std::string& name) const {
  const auto& specs = Parameters();
  for (size_t i = 0; i < specs.size(); ++i) {
    if (specs[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

bool ContactLaw::IsValid(std::span<const double> p, const ContactBody& body,
                         std::string* error) const {
  const auto& specs = Parameters();
  auto fail = [&](const std::string& msg) {
    if (error) *error = Name() + ": " + msg;
    return false;
  };
  if (p.size() != specs.size()) {
    return fail("expected " + std::to_string(specs.size()) + " parameters, got " +
                std::to_string(p.size()));
  }
  if (!(body.mass_kg > 0.0) || !std::isfinite(body.mass_kg)) {
    return fail("effective mass must be positive and finite");
  }
  if (!(body.radius_m > 0.0) || !std::isfinite(body.radius_m)) {
    return fail("effective radius must be positive and finite");
  }
  for (size_t i = 0; i < specs.size(); ++i) {
    const auto& s = specs[i];
    if (!std::isfinite(p[i]) || p[i] < s.lower || p[i] > s.upper) {
      std::ostringstream os;
      os << "parameter " << s.name << " = " << p[i] << " " << s.unit << " is outside [" << s.lower
         << ", " << s.upper << "]";
      return fail(os.str());
    }
  }
  return true;
}

std::optional<double> ContactLaw::Restitution(std::span<const double>, const ContactBody&,
                                              double) const {
  return std::nullopt;
}

std::optional<double> ContactLaw::ContactTime(std::span<const double>, const ContactBody&,
                                              double) const {
  return std::nullopt;
}

std::optional<ContactOutcome> ContactLaw::SolveContact(std::span<const double>, const ContactBody&,
                                                       double) const {
  return std::nullopt;
}

std::optional<std::vector<double>> ContactLaw::DampingForRestitution(std::span<const double>,
                                                                     const ContactBody&, double,
                                                                     double) const {
  return std::nullopt;
}

bool ContactLaw::RestitutionGradient(std::span<const double>, const ContactBody&, double, double*,
                                     double*) const {
  return false;
}

}  // namespace bouncecal

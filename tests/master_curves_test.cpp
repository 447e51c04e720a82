// The Hertz-type laws' master curves are computed at build time (tools/generate/master_curves.cpp
// writes a generated source); the build-time nodes must equal the run-time computation, node
// for node (same code, same compiler, numbers printed with 17 digits: bit-identical).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "physics/laws/master_curves.hpp"

namespace bouncecal::laws {
namespace {

void ExpectEqualNodes(const MasterNodes& built, const MasterNodes& computed, const char* what) {
  ASSERT_EQ(built.damping.size(), computed.damping.size()) << what;
  const std::vector<double> MasterNodes::*fields[] = {
      &MasterNodes::damping, &MasterNodes::restitution, &MasterNodes::restitution_slope,
      &MasterNodes::contact_time, &MasterNodes::contact_time_slope};
  int differing = 0;
  double worst = 0.0;
  for (const auto field : fields) {
    for (size_t i = 0; i < built.damping.size(); ++i) {
      const double a = (built.*field)[i], b = (computed.*field)[i];
      if (a != b) ++differing;
      worst = std::max(worst, std::abs(a - b) / std::max(std::abs(b), 1e-300));
    }
  }
  EXPECT_EQ(differing, 0) << what << ": " << differing
                          << " numbers differ from the run-time computation (worst relative "
                          << worst << ")";
}

TEST(MasterCurves, TsujiBuildTimeNodesEqualTheRunTimeComputation) {
  const MasterNodes& built = TsujiNodes();
  EXPECT_EQ(built.damping.size(), static_cast<size_t>(kTsujiNodeCount));
  EXPECT_EQ(built.damping.front(), 0.0);
  EXPECT_EQ(built.damping.back(), kTsujiAlphaMax);
  EXPECT_NEAR(built.restitution.front(), 1.0, 1e-11);  // no damping: elastic
  ExpectEqualNodes(built, ComputeTsujiNodes(), "hertz-tsuji");
}

TEST(MasterCurves, ViscoelasticBuildTimeNodesEqualTheRunTimeComputation) {
  const MasterNodes& built = ViscoelasticNodes();
  EXPECT_EQ(built.damping.size(), static_cast<size_t>(kViscoelasticNodeCount));
  EXPECT_EQ(built.damping.back(), kViscoelasticBMax);
  ExpectEqualNodes(built, ComputeViscoelasticNodes(), "hertz-viscoelastic");
}

TEST(MasterCurves, RestitutionFallsAndSlopesAgreeWithTheNodes) {
  for (const MasterNodes* n : {&TsujiNodes(), &ViscoelasticNodes()}) {
    for (size_t i = 1; i < n->damping.size(); ++i) {
      ASSERT_LT(n->restitution[i], n->restitution[i - 1]) << i;
      ASSERT_LT(n->restitution_slope[i], 0.0) << i;
      // The tabulated slope is the secant's within the curvature of one cell.
      const double h = n->damping[i] - n->damping[i - 1];
      const double secant = (n->restitution[i] - n->restitution[i - 1]) / h;
      EXPECT_NEAR(secant, 0.5 * (n->restitution_slope[i] + n->restitution_slope[i - 1]),
                  0.05 * std::abs(secant))
          << i;
    }
  }
}

}  // namespace
}  // namespace bouncecal::laws

// The program's forwarders to Ceres's sparse and LAPACK back ends (src/cli/lazy_linear_algebra.cpp,
// cmake/lazy_ceres_backends.cmake): this test binary links them instead of the back ends, as the
// program does. Checked: no back end (nor the BLAS) is loaded at start-up or by the dense-QR
// solve the fit uses; every back end, reached through the forwarders, gives the answer of
// Eigen's dense QR; the program itself loads none of them for a whole calibration.
#include <link.h>

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "test_util.hpp"

namespace {

// True when a shared object whose file name contains `part` is loaded in this process.
bool Loaded(const std::string& part) {
  struct Search {
    const std::string* part;
    bool found = false;
  } search{&part};
  dl_iterate_phdr(
      [](dl_phdr_info* info, size_t, void* data) {
        auto* s = static_cast<Search*>(data);
        if (info->dlpi_name != nullptr &&
            std::string(info->dlpi_name).find(*s->part) != std::string::npos) {
          s->found = true;
        }
        return 0;
      },
      &search);
  return search.found;
}

// y = exp(m x + c) (Ceres's curve-fitting example), m and c in two parameter blocks so that the
// sparse solvers see a sparse problem.
struct ExponentialResidual {
  ExponentialResidual(double x, double y) : x_(x), y_(y) {}
  template <typename T>
  bool operator()(const T* const m, const T* const c, T* residual) const {
    residual[0] = y_ - exp(m[0] * x_ + c[0]);
    return true;
  }
  const double x_, y_;
};

struct Fit {
  double m = 0.0, c = 0.0;
  bool usable = false;
};

// Fits m = 0.3, c = 0.1 to 60 points with a deterministic +-1e-3 ripple, from (0, 0).
Fit Solve(ceres::LinearSolverType solver, ceres::DenseLinearAlgebraLibraryType dense,
          ceres::SparseLinearAlgebraLibraryType sparse) {
  Fit fit;
  ceres::Problem problem;
  for (int i = 0; i < 60; ++i) {
    const double x = 0.05 * i;
    const double y = std::exp(0.3 * x + 0.1) + 1e-3 * std::sin(7.0 * i);
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ExponentialResidual, 1, 1, 1>(
                                 new ExponentialResidual(x, y)),
                             nullptr, &fit.m, &fit.c);
  }
  ceres::Solver::Options options;
  options.linear_solver_type = solver;
  options.dense_linear_algebra_library_type = dense;
  options.sparse_linear_algebra_library_type = sparse;
  options.function_tolerance = 1e-14;
  options.parameter_tolerance = 1e-14;
  options.gradient_tolerance = 1e-16;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  fit.usable = summary.IsSolutionUsable();
  return fit;
}

Fit Reference() { return Solve(ceres::DENSE_QR, ceres::EIGEN, ceres::SUITE_SPARSE); }

void ExpectSameFit(const Fit& fit, const Fit& reference) {
  ASSERT_TRUE(fit.usable);
  // The same least-squares minimum; measured differences ~1e-15, bound 1e-10.
  EXPECT_NEAR(fit.m, reference.m, 1e-10);
  EXPECT_NEAR(fit.c, reference.c, 1e-10);
}

// First in this file: in one process (the binary run alone) later tests load the back ends.
TEST(LazyLinearAlgebra, NothingLoadedUntilABackEndIsCalled) {
  EXPECT_FALSE(Loaded("libcholmod"));
  EXPECT_FALSE(Loaded("libcxsparse"));
  EXPECT_FALSE(Loaded("liblapack"));
  EXPECT_FALSE(Loaded("blas"));
  const Fit reference = Reference();
  ASSERT_TRUE(reference.usable);
  EXPECT_NEAR(reference.m, 0.3, 1e-3);
  EXPECT_NEAR(reference.c, 0.1, 1e-3);
  EXPECT_FALSE(Loaded("libcholmod"));
  EXPECT_FALSE(Loaded("liblapack"));
  EXPECT_FALSE(Loaded("blas"));
}

TEST(LazyLinearAlgebra, LapackQrThroughTheForwarders) {
  ExpectSameFit(Solve(ceres::DENSE_QR, ceres::LAPACK, ceres::SUITE_SPARSE), Reference());
  EXPECT_TRUE(Loaded("liblapack"));
}

TEST(LazyLinearAlgebra, LapackCholeskyThroughTheForwarders) {
  ExpectSameFit(Solve(ceres::DENSE_NORMAL_CHOLESKY, ceres::LAPACK, ceres::SUITE_SPARSE),
                Reference());
  EXPECT_TRUE(Loaded("liblapack"));
}

TEST(LazyLinearAlgebra, CholmodThroughTheForwarders) {
  ExpectSameFit(Solve(ceres::SPARSE_NORMAL_CHOLESKY, ceres::EIGEN, ceres::SUITE_SPARSE),
                Reference());
  EXPECT_TRUE(Loaded("libcholmod"));
}

TEST(LazyLinearAlgebra, CxsparseThroughTheForwarders) {
  ExpectSameFit(Solve(ceres::SPARSE_NORMAL_CHOLESKY, ceres::EIGEN, ceres::CX_SPARSE), Reference());
  EXPECT_TRUE(Loaded("libcxsparse"));
}

// The program: a whole calibration of the bundled recording loads no back end and no BLAS
// (LD_DEBUG=files makes the dynamic loader name every object it loads).
TEST(LazyLinearAlgebra, ProgramCalibratesWithoutLoadingThem) {
  const std::string root = BOUNCECAL_SOURCE_DIR;
  const auto r = bouncecal::testing_util::RunCommand(
      std::string("LD_DEBUG=files ") + BOUNCECAL_BINARY,
      "calibrate " + root + "/data/default_steel_copper.flac --scene " + root +
          "/data/default_steel_copper.toml --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("file=libsndfile"), std::string::npos) << "LD_DEBUG output missing";
  EXPECT_EQ(r.err.find("file=libcholmod"), std::string::npos);
  EXPECT_EQ(r.err.find("file=libcxsparse"), std::string::npos);
  EXPECT_EQ(r.err.find("file=liblapack"), std::string::npos);
  EXPECT_EQ(r.err.find("blas"), std::string::npos);
}

// libcrypto (SHA-256 of the inputs, src/io/provenance.cpp) is opened by the first checksum, not
// linked: a detection never loads it; a calibration, whose result names its inputs' checksums,
// loads it and gets the checksum of the recording.
TEST(LazyLibcrypto, OnlyTheCommandsThatChecksumLoadIt) {
  const std::string root = BOUNCECAL_SOURCE_DIR;
  const std::string rec = root + "/data/default_steel_copper.flac";
  const auto detect = bouncecal::testing_util::RunCommand(
      std::string("LD_DEBUG=files ") + BOUNCECAL_BINARY, "detect " + rec + " --json");
  ASSERT_EQ(detect.exit_code, 0) << detect.err;
  EXPECT_NE(detect.err.find("file=libsndfile"), std::string::npos) << "LD_DEBUG output missing";
  EXPECT_EQ(detect.err.find("file=libcrypto"), std::string::npos);
  const auto calibrate = bouncecal::testing_util::RunCommand(
      std::string("LD_DEBUG=files ") + BOUNCECAL_BINARY,
      "calibrate " + rec + " --scene " + root + "/data/default_steel_copper.toml --json --quiet");
  ASSERT_EQ(calibrate.exit_code, 0) << calibrate.err;
  EXPECT_NE(calibrate.err.find("file=libcrypto"), std::string::npos);
  // The provenance names the recording's checksum, as sha256sum (coreutils) computes it.
  const auto sum = bouncecal::testing_util::RunCommand("sha256sum", rec);
  ASSERT_EQ(sum.exit_code, 0) << sum.err;
  const std::string digest = sum.out.substr(0, 64);
  EXPECT_NE(calibrate.out.find("\"" + digest + "\""), std::string::npos) << digest;
}

}  // namespace

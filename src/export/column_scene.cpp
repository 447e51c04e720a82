// Seed 003's column (column.hpp): bead sizes, the pour, the floor, the rest criterion,
// the memory estimate and the refusals. Contacts and the time step: column_contact.cpp.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/export/column.hpp"
#include "export/column_deck.hpp"

namespace bouncecal {
namespace {

// Bead diameters: normal within the paper's 4.9-5.9 mm, read as mean +- 2 sigma (95 % of a normal
// inside the measured range; the paper gives the range only), truncated to the range.
constexpr double kDiameterSigmaPerHalfRange = 0.5;
// The pour: beads placed one by one at random, seeded (random sequential addition), each at
// least 1 % of d_max from the others and the walls, in a loose rain of solid fraction 0.3 above
// the floor, below the 0.38 at which random sequential addition of spheres jams (Torquato,
// Random Heterogeneous Materials, 2002, sec. 3.4), so placing never stalls; they then fall and
// settle behind the gate, as the paper's beads were poured. (A jittered fcc lattice, tried first,
// gave the same final height within 2 mm at scale 1/3.)
constexpr double kPourGap = 0.01, kPourSolidFraction = 0.3;
constexpr int kMaxTries = 100000;
// Enough beads to fill the column at random close packing (0.64, Scott & Kilgour 1969), the
// densest a poured packing reaches, one bead diameter above the column height: the settled pile
// always overtops the column and is trimmed to it.
constexpr double kRandomClosePacking = 0.64;
// The sandpaper: fixed spheres of half the mean bead diameter, 0.1 % apart (so they never touch
// each other); the paper gives no size ("fixed small spheres").
constexpr double kFloorToBead = 0.5, kFloorGap = 1.001;
// At rest: rms bead speed below a tenth of a mean diameter per frame of the paper's 25 fps
// camera (what its video could not resolve).
constexpr double kRestDiametersPerFrame = 0.1;
// Settling stops at rest, or 0.5 s after the pour's free fall (the paper's collapse comes to
// rest within 0.52 s); the front and profile are sampled every 10 ms (4 per video frame).
constexpr double kSettleExtra_s = 0.5, kDumpInterval_s = 0.01;
// At least three beads along the column's 100 mm: fewer and the "column" is a stack.
constexpr double kMinBeadsAcross = 3.0;
// The column's length in beads: the largest bead plus the pour's wall gaps.
constexpr double kBeadSpan = 1.0 + 2.0 * kPourGap;
// Peak resident memory, measured with /usr/bin/time -v at the start of the full column (39.6 k
// spheres) and of scale 0.25 (1.15 k): LAMMPS 29 Sep 2021 64 and 34 MB (0.8 kB per sphere over
// a 33 MB process), Yade 2023.02a 392 and 259 MB (3.5 kB per sphere over 255 MB). The per-sphere
// figures are taken ~2.5x (2 and 8 kB) to allow for the contact histories of the settled pile,
// which the start does not have yet.
constexpr double kLammpsBytesPerSphere = 2.0e3, kLammpsBytesPerRank = 40e6;
constexpr double kYadeBytesPerSphere = 8.0e3, kYadeBytesBase = 300e6;

double Cube(double x) { return x * x * x; }

// Mean of d^3 for a normal(mu, sigma) truncated to [lo, hi] (numerical, 400 panels).
double MeanCube(double mu, double sigma, double lo, double hi) {
  double num = 0.0, den = 0.0;
  const int n = 400;
  for (int i = 0; i < n; ++i) {
    const double d = lo + (i + 0.5) * (hi - lo) / n;
    const double w = std::exp(-0.5 * (d - mu) * (d - mu) / (sigma * sigma));
    num += w * Cube(d);
    den += w;
  }
  return num / den;
}

}  // namespace

double QPhiFromFrictionAngle(double phi_rad) {
  // seed 003 eq. 11: q^2 = (-3 (4 t^2 - 3) - 9 sqrt(1 - 4 t^2)) / (2 (4 t^2 + 3)), t = tan phi.
  const double t2 = std::tan(phi_rad) * std::tan(phi_rad);
  if (!(4.0 * t2 <= 1.0)) return std::nan("");
  const double q2 =
      (-3.0 * (4.0 * t2 - 3.0) - 9.0 * std::sqrt(1.0 - 4.0 * t2)) / (2.0 * (4.0 * t2 + 3.0));
  return std::sqrt(q2);
}

double MachineMemoryBytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? static_cast<double>(pages) * static_cast<double>(page) : 0.0;
}

bool ColumnOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(scale > 0.0 && scale <= 100.0))
    return fail("column scale = " + FormatShortest(scale) + " must be in (0, 100]");
  if (particles < 0)
    return fail("column particles = " + std::to_string(particles) + " must be >= 1");
  if (!(restitution == 0.0 || (restitution > 0.0 && restitution < 1.0))) {
    return fail("column restitution = " + FormatShortest(restitution) +
                " must be in (0, 1), or 0 for the fits'");
  }
  if (!(rolling_friction >= 0.0 && rolling_friction <= 1.0)) {
    return fail("rolling friction = " + FormatShortest(rolling_friction) + " must be in [0, 1]");
  }
  if (!(dt_e_error > 0.0 && dt_e_error < 0.1)) {
    return fail("column dt_e_error = " + FormatShortest(dt_e_error) + " must be in (0, 0.1)");
  }
  if (!(max_collapse_s > 0.0 && max_collapse_s <= 60.0)) {
    return fail("column max_collapse_s = " + FormatShortest(max_collapse_s) +
                " must be in (0, 60]");
  }
  if (ranks < 1 || ranks > 4096)
    return fail("ranks = " + std::to_string(ranks) + " must be in [1, 4096]");
  return true;
}

namespace exporter {

ColumnPlan ColumnGeometry(const ColumnOptions& o, ExportTarget target) {
  ColumnPlan p;
  p.target = target;
  p.seed = o.seed;
  p.scale =
      o.particles > 0 ? std::cbrt(static_cast<double>(o.particles) / ColumnPaper::kBeads) : o.scale;
  p.d_min_m = ColumnPaper::kDiameterMin_m / p.scale;
  p.d_max_m = ColumnPaper::kDiameterMax_m / p.scale;
  p.d_mean_m = 0.5 * (p.d_min_m + p.d_max_m);
  p.d_sigma_m = kDiameterSigmaPerHalfRange * 0.5 * (p.d_max_m - p.d_min_m);
  p.floor_diameter_m = kFloorToBead * p.d_mean_m;
  p.rolling_friction = o.rolling_friction;
  p.max_collapse_s = o.max_collapse_s;
  p.q_phi = QPhiFromFrictionAngle(ColumnPaper::kReposeAngle_deg * M_PI / 180.0);
  const double across = ColumnPaper::kColumnLength_m / (kBeadSpan * p.d_max_m);
  const std::string what = o.particles > 0 ? "--particles " + std::to_string(o.particles)
                                           : "--scale " + FormatShortest(p.scale);
  if (across < kMinBeadsAcross) {
    throw Error(ErrorCode::kBadParameter,
                what + ": beads up to " + FormatShortest(p.d_max_m * 1e3) + " mm across leave " +
                    FormatShortest(std::floor(across * 10) / 10) +
                    " of them along the column's 100 mm; at least " +
                    FormatShortest(kMinBeadsAcross) + " must fit (--scale >= " +
                    FormatShortest(kMinBeadsAcross * kBeadSpan * ColumnPaper::kDiameterMax_m /
                                   ColumnPaper::kColumnLength_m) +
                    ", --particles >= " +
                    std::to_string(static_cast<int>(
                        std::ceil(ColumnPaper::kBeads *
                                  Cube(kMinBeadsAcross * kBeadSpan * ColumnPaper::kDiameterMax_m /
                                       ColumnPaper::kColumnLength_m)))) +
                    ")");
  }
  const double v_mean = M_PI / 6.0 * MeanCube(p.d_mean_m, p.d_sigma_m, p.d_min_m, p.d_max_m);
  const double fill_volume = ColumnPaper::kColumnLength_m * ColumnPaper::kBoxWidth_m *
                             (ColumnPaper::kColumnHeight_m + p.d_mean_m);
  p.expected_beads = static_cast<int>(std::lround(ColumnPaper::kBeads * Cube(p.scale)));
  const double needed = std::ceil(kRandomClosePacking * fill_volume / v_mean);
  p.floor_spheres =
      static_cast<int>(std::floor(ColumnPaper::kBoxLength_m / (kFloorGap * p.floor_diameter_m))) *
      static_cast<int>(std::floor(ColumnPaper::kBoxWidth_m / (kFloorGap * p.floor_diameter_m)));
  // Memory before anything is built: the estimate needs only the counts.
  const double spheres = needed + p.floor_spheres;
  p.memory_bytes = target == ExportTarget::kYade
                       ? kYadeBytesBase + kYadeBytesPerSphere * spheres
                       : o.ranks * kLammpsBytesPerRank + kLammpsBytesPerSphere * spheres;
  const double machine = MachineMemoryBytes();
  if (machine > 0.0 && p.memory_bytes > machine) {
    throw Error(ErrorCode::kBadParameter,
                what + ": ~" + std::to_string(static_cast<long long>(spheres)) + " spheres need ~" +
                    FormatShortest(std::round(p.memory_bytes / 1e8) / 10) + " GB in " +
                    ExportTargetName(target) + ", more than this machine's " +
                    FormatShortest(std::round(machine / 1e8) / 10) + " GB; not exported");
  }
  p.poured_beads = static_cast<int>(needed);
  p.pour_bottom_m = p.floor_diameter_m + (0.5 + kPourGap) * p.d_max_m;
  p.pour_top_m = p.pour_bottom_m +
                 needed * v_mean /
                     (kPourSolidFraction * ColumnPaper::kColumnLength_m * ColumnPaper::kBoxWidth_m);
  p.box_top_m = p.pour_top_m + p.d_max_m;
  p.rest_speed_m_s = kRestDiametersPerFrame * p.d_mean_m / ColumnPaper::kFrameInterval_s;
  p.settle_min_s =
      std::sqrt(2.0 * std::max(0.0, p.pour_top_m - ColumnPaper::kColumnHeight_m) / 9.8);
  p.settle_max_s = p.settle_min_s + kSettleExtra_s;
  p.dump_interval_s = kDumpInterval_s;
  return p;
}

}  // namespace exporter

std::vector<ColumnSphere> ColumnSpheres(const ColumnPlan& p) {
  std::vector<ColumnSphere> out;
  std::mt19937_64 rng(p.seed);
  std::normal_distribution<double> size(p.d_mean_m, p.d_sigma_m);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  out.reserve(static_cast<size_t>(p.poured_beads + p.floor_spheres));
  // Cells of the largest bead's span: a new bead can only touch beads in the 27 around it.
  const double cell = kBeadSpan * p.d_max_m, gap = kPourGap * p.d_max_m;
  const double lx = ColumnPaper::kColumnLength_m, ly = ColumnPaper::kBoxWidth_m;
  const int nx = static_cast<int>(lx / cell) + 1, ny = static_cast<int>(ly / cell) + 1;
  const int nz = static_cast<int>((p.pour_top_m + cell) / cell) + 1;
  std::vector<std::vector<int>> cells(static_cast<size_t>(nx * ny * nz));
  auto index = [&](double x, double y, double z) {
    const int i = std::clamp(static_cast<int>(x / cell), 0, nx - 1);
    const int j = std::clamp(static_cast<int>(y / cell), 0, ny - 1);
    const int k = std::clamp(static_cast<int>(z / cell), 0, nz - 1);
    return std::array<int, 3>{i, j, k};
  };
  auto free = [&](double x, double y, double z, double d) {
    const auto c = index(x, y, z);
    for (int i = std::max(0, c[0] - 1); i <= std::min(nx - 1, c[0] + 1); ++i) {
      for (int j = std::max(0, c[1] - 1); j <= std::min(ny - 1, c[1] + 1); ++j) {
        for (int k = std::max(0, c[2] - 1); k <= std::min(nz - 1, c[2] + 1); ++k) {
          for (int n : cells[static_cast<size_t>((k * ny + j) * nx + i)]) {
            const ColumnSphere& o = out[static_cast<size_t>(n)];
            const double reach = 0.5 * (d + o.diameter_m) + gap;
            const double dx = x - o.x_m, dy = y - o.y_m, dz = z - o.z_m;
            if (dx * dx + dy * dy + dz * dz < reach * reach) return false;
          }
        }
      }
    }
    return true;
  };
  for (int b = 0; b < p.poured_beads; ++b) {
    double d = size(rng);
    while (d < p.d_min_m || d > p.d_max_m) d = size(rng);
    const double m = 0.5 * d + gap;
    bool placed = false;
    for (int t = 0; t < kMaxTries && !placed; ++t) {
      const double x = m + unit(rng) * (lx - 2.0 * m), y = m + unit(rng) * (ly - 2.0 * m);
      const double z = p.pour_bottom_m + unit(rng) * (p.pour_top_m - p.pour_bottom_m);
      if (!free(x, y, z, d)) continue;
      const auto c = index(x, y, z);
      cells[static_cast<size_t>((c[2] * ny + c[1]) * nx + c[0])].push_back(
          static_cast<int>(out.size()));
      out.push_back({1, d, x, y, z});
      placed = true;
    }
    // At a solid fraction of 0.3 a free place is found within a few tries (jamming is at 0.38).
    if (!placed) throw Error(ErrorCode::kInternal, "column: the pour found no free place");
  }
  const double f = p.floor_diameter_m, pitch = kFloorGap * f;
  const int fx = static_cast<int>(std::floor(ColumnPaper::kBoxLength_m / pitch));
  const int fy = static_cast<int>(std::floor(ColumnPaper::kBoxWidth_m / pitch));
  for (int i = 0; i < fx; ++i) {
    for (int j = 0; j < fy; ++j)
      out.push_back({2, f, (i + 0.5) * pitch, (j + 0.5) * pitch, 0.5 * f});
  }
  return out;
}

}  // namespace bouncecal

// physics/dop853.hpp — Hairer's DOP853: an explicit Runge-Kutta pair of order 8 with an error
// estimator of orders 5 and 3 and a continuous extension of order 7, for the contact integrator
// at tight tolerances (internal header).
//
// Method: Dormand & Prince's order-8 pair as refined by Hairer, in Hairer, Norsett & Wanner,
// Solving ODEs I, 2nd ed. (1993), §II.10 ("DOP853"): 12 stages per step plus the derivative at
// the end (first same as last), the error estimate
//   err = |h| E5^2 / sqrt(n (E5^2 + 0.01 E3^2)),  E5, E3 the RMS-free sums of the scaled
// 5th- and 3rd-order error vectors (HNW §II.10, eq. 10.10 and the code's ERR/ERR2), and the
// dense output of order 7 that needs three more stages per step (computed here only for the
// steps whose dense output is asked for: event steps). The coefficients are the published
// ones (the tables distributed with Hairer's dop853.f, also in SciPy's
// integrate/_ivp/dop853_coefficients.py), to 30 digits; the implementation is this file's.
// Why here: at the default tolerance (1e-9) the number of steps scales as tol^(-1/8) instead of
// dopri5's tol^(-1/5) — about 4x fewer steps per contact for twice the stages per step
// (tools/bench_simulate). The interface is dopri5::Stepper's: values and ceres::Jet states, the
// error control on the values only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <type_traits>
#include <utility>

#include "physics/dopri5.hpp"
#include "physics/scalar.hpp"

namespace bouncecal::dop853 {

using scalar::Value;

inline constexpr size_t kStages = 16;  // 12 step stages, f(x1), 3 for the dense output
inline constexpr size_t kEnd = 12;     // stage index of f(x1, t + h)
using Row = std::array<double, kStages>;

inline constexpr Row kC = {0.0,
                           0.526001519587677318785587544488e-01,
                           0.789002279381515978178381316732e-01,
                           0.118350341907227396726757197510,
                           0.281649658092772603273242802490,
                           0.333333333333333333333333333333,
                           0.25,
                           0.307692307692307692307692307692,
                           0.651282051282051282051282051282,
                           0.6,
                           0.857142857142857142857142857142,
                           1.0,
                           1.0,
                           0.1,
                           0.2,
                           0.777777777777777777777777777778};
inline constexpr std::array<Row, kStages> kA = {{
    {},  // stage 1: x
    {5.26001519587677318785587544488e-2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0},  // stage 2
    {1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2, 0.0, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 3
    {2.95875854768068491816892993775e-2, 0.0, 8.87627564304205475450678981324e-2, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 4
    {2.41365134159266685502369798665e-1, 0.0, -8.84549479328286085344864962717e-1,
     9.24834003261792003115737966543e-1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
     0.0},  // stage 5
    {3.7037037037037037037037037037e-2, 0.0, 0.0, 1.70828608729473871279604482173e-1,
     1.25467687566822425016691814123e-1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
     0.0},  // stage 6
    {3.7109375e-2, 0.0, 0.0, 1.70252211019544039314978060272e-1, 6.02165389804559606850219397283e-2,
     -1.7578125e-2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 7
    {3.70920001185047927108779319836e-2, 0.0, 0.0, 1.70383925712239993810214054705e-1,
     1.07262030446373284651809199168e-1, -1.53194377486244017527936158236e-2,
     8.27378916381402288758473766002e-3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 8
    {6.24110958716075717114429577812e-1, 0.0, 0.0, -3.36089262944694129406857109825,
     -8.68219346841726006818189891453e-1, 2.75920996994467083049415600797e1,
     2.01540675504778934086186788979e1, -4.34898841810699588477366255144e1, 0.0, 0.0, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0},  // stage 9
    {4.77662536438264365890433908527e-1, 0.0, 0.0, -2.48811461997166764192642586468,
     -5.90290826836842996371446475743e-1, 2.12300514481811942347288949897e1,
     1.52792336328824235832596922938e1, -3.32882109689848629194453265587e1,
     -2.03312017085086261358222928593e-2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 10
    {-9.3714243008598732571704021658e-1, 0.0, 0.0, 5.18637242884406370830023853209,
     1.09143734899672957818500254654, -8.14978701074692612513997267357,
     -1.85200656599969598641566180701e1, 2.27394870993505042818970056734e1,
     2.49360555267965238987089396762, -3.0467644718982195003823669022, 0.0, 0.0, 0.0, 0.0, 0.0,
     0.0},  // stage 11
    {2.27331014751653820792359768449, 0.0, 0.0, -1.05344954667372501984066689879e1,
     -2.00087205822486249909675718444, -1.79589318631187989172765950534e1,
     2.79488845294199600508499808837e1, -2.85899827713502369474065508674,
     -8.87285693353062954433549289258, 1.23605671757943030647266201528e1,
     6.43392746015763530355970484046e-1, 0.0, 0.0, 0.0, 0.0, 0.0},  // stage 12
    {5.42937341165687622380535766363e-2, 0.0, 0.0, 0.0, 0.0, 4.45031289275240888144113950566,
     1.89151789931450038304281599044, -5.8012039600105847814672114227,
     3.1116436695781989440891606237e-1, -1.52160949662516078556178806805e-1,
     2.01365400804030348374776537501e-1, 4.47106157277725905176885569043e-2, 0.0, 0.0, 0.0,
     0.0},  // stage 13
    {5.61675022830479523392909219681e-2, 0.0, 0.0, 0.0, 0.0, 0.0,
     2.53500210216624811088794765333e-1, -2.46239037470802489917441475441e-1,
     -1.24191423263816360469010140626e-1, 1.5329179827876569731206322685e-1,
     8.20105229563468988491666602057e-3, 7.56789766054569976138603589584e-3, -8.298e-3, 0.0, 0.0,
     0.0},  // stage 14
    {3.18346481635021405060768473261e-2, 0.0, 0.0, 0.0, 0.0, 2.83009096723667755288322961402e-2,
     5.35419883074385676223797384372e-2, -5.49237485713909884646569340306e-2, 0.0, 0.0,
     -1.08347328697249322858509316994e-4, 3.82571090835658412954920192323e-4,
     -3.40465008687404560802977114492e-4, 1.41312443674632500278074618366e-1, 0.0,
     0.0},  // stage 15
    {-4.28896301583791923408573538692e-1, 0.0, 0.0, 0.0, 0.0, -4.69762141536116384314449447206,
     7.68342119606259904184240953878, 4.06898981839711007970213554331,
     3.56727187455281109270669543021e-1, 0.0, 0.0, 0.0, -1.39902416515901462129418009734e-3,
     2.9475147891527723389556272149, -9.15095847217987001081870187138, 0.0},  // stage 16
}};
inline constexpr Row kE5 = {0.1312004499419488073250102996e-1,
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            -0.1225156446376204440720569753e+1,
                            -0.4957589496572501915214079952,
                            0.1664377182454986536961530415e+1,
                            -0.3503288487499736816886487290,
                            0.3341791187130174790297318841,
                            0.8192320648511571246570742613e-1,
                            -0.2235530786388629525884427845e-1,
                            0.0,
                            0.0,
                            0.0,
                            0.0};
inline constexpr std::array<Row, 4> kD = {{
    {-0.84289382761090128651353491142e+1, 0.0, 0.0, 0.0, 0.0, 0.56671495351937776962531783590,
     -0.30689499459498916912797304727e+1, 0.23846676565120698287728149680e+1,
     0.21170345824450282767155149946e+1, -0.87139158377797299206789907490,
     0.22404374302607882758541771650e+1, 0.63157877876946881815570249290,
     -0.88990336451333310820698117400e-1, 0.18148505520854727256656404962e+2,
     -0.91946323924783554000451984436e+1, -0.44360363875948939664310572000e+1},
    {0.10427508642579134603413151009e+2, 0.0, 0.0, 0.0, 0.0, 0.24228349177525818288430175319e+3,
     0.16520045171727028198505394887e+3, -0.37454675472269020279518312152e+3,
     -0.22113666853125306036270938578e+2, 0.77334326684722638389603898808e+1,
     -0.30674084731089398182061213626e+2, -0.93321305264302278729567221706e+1,
     0.15697238121770843886131091075e+2, -0.31139403219565177677282850411e+2,
     -0.93529243588444783865713862664e+1, 0.35816841486394083752465898540e+2},
    {0.19985053242002433820987653617e+2, 0.0, 0.0, 0.0, 0.0, -0.38703730874935176555105901742e+3,
     -0.18917813819516756882830838328e+3, 0.52780815920542364900561016686e+3,
     -0.11573902539959630126141871134e+2, 0.68812326946963000169666922661e+1,
     -0.10006050966910838403183860980e+1, 0.77771377980534432092869265740,
     -0.27782057523535084065932004339e+1, -0.60196695231264120758267380846e+2,
     0.84320405506677161018159903784e+2, 0.11992291136182789328035130030e+2},
    {-0.25693933462703749003312586129e+2, 0.0, 0.0, 0.0, 0.0, -0.15418974869023643374053993627e+3,
     -0.23152937917604549567536039109e+3, 0.35763911791061412378285349910e+3,
     0.93405324183624310003907691704e+2, -0.37458323136451633156875139351e+2,
     0.10409964950896230045147246184e+3, 0.29840293426660503123344363579e+2,
     -0.43533456590011143754432175058e+2, 0.96324553959188282948394950600e+2,
     -0.39177261675615439165231486172e+2, -0.14972683625798562581422125276e+3},
}};
// The 8th-order weights (the row of the end point) and the 3rd-order error weights
// E3 = b - bhh (bhh: HNW's BHH1..3, on stages 1, 9 and 12).
inline constexpr Row kB = kA[kEnd];
inline constexpr Row kE3 = [] {
  Row e = kB;
  e[0] -= 0.244094488188976377952755905512;
  e[8] -= 0.733846688281611857341361741547;
  e[11] -= 0.220588235294117647058823529412e-1;
  return e;
}();

// Each row of kA and kD as an object of its own: a row is passed to RowSum as a template
// argument, and a reference to a subobject of an array is not one clang 14 accepts (C++20
// allows it; GCC does).
template <size_t S>
inline constexpr Row kARow = kA[S];
template <size_t R>
inline constexpr Row kDRow = kD[R];

// Pointers to the stage derivatives k_0 .. k_15 of one step (k_0 = f(x), k_12 = f(x1)).
template <class T, size_t N>
using StagePointers = std::array<const std::array<T, N>*, kStages>;

// out_i = x_i + h sum_j kRow[j] k_j[i] for i < n: the zero coefficients are dropped at compile
// time; a ceres::Jet's value and derivative parts are summed over raw arrays (as
// dopri5::Combine, for the same reason).
// Components whose bit in kMask is clear are copied from x (stage inputs the right-hand side
// does not read: see Stepper::Step).
template <const Row& kRow, unsigned kMask, class T, size_t N, size_t... J>
inline void RowSum(const std::array<T, N>& x, double h, const StagePointers<T, N>& k,
                   std::array<T, N>& out, size_t n, std::index_sequence<J...>) {
  if constexpr (std::is_same_v<T, double>) {
    for (size_t i = 0; i < n; ++i) {
      if (!((kMask >> i) & 1u)) {
        out[i] = x[i];
        continue;
      }
      double s = 0.0;
      ((kRow[J] != 0.0 ? void(s += kRow[J] * (*k[J])[i]) : void()), ...);
      out[i] = x[i] + h * s;
    }
  } else {
    constexpr int kN = static_cast<int>(decltype(x[0].v)::RowsAtCompileTime);
    for (size_t i = 0; i < n; ++i) {
      double s = 0.0;
      ((kRow[J] != 0.0 ? void(s += kRow[J] * (*k[J])[i].a) : void()), ...);
      double v[kN];
      const double* xv = x[i].v.data();
      for (int j = 0; j < kN; ++j) v[j] = xv[j];
      auto add = [&](double c, const T& kj) {
        const double* kv = kj.v.data();
        for (int j = 0; j < kN; ++j) v[j] += c * kv[j];
      };
      ((kRow[J] != 0.0 ? add(h * kRow[J], (*k[J])[i]) : void()), ...);
      out[i].a = x[i].a + h * s;
      double* ov = out[i].v.data();
      for (int j = 0; j < kN; ++j) ov[j] = v[j];
    }
  }
}
template <const Row& kRow, unsigned kMask = ~0u, class T, size_t N>
inline void RowSum(const std::array<T, N>& x, double h, const StagePointers<T, N>& k,
                   std::array<T, N>& out, size_t n) {
  RowSum<kRow, kMask>(x, h, k, out, n, std::make_index_sequence<kStages>{});
}

// The value part of sum_j kRow[j] k_j[i].
template <const Row& kRow, class T, size_t N, size_t... J>
inline double RowValue(const StagePointers<T, N>& k, size_t i, std::index_sequence<J...>) {
  double s = 0.0;
  ((kRow[J] != 0.0 ? void(s += kRow[J] * Value((*k[J])[i])) : void()), ...);
  return s;
}

// One DOP853 integrator; the stages of the last step are kept for its dense output.
// Sys: void operator()(const State& x, State& dxdt, double t) const.
template <class T, size_t N>
class Stepper {
 public:
  using State = std::array<T, N>;
  static constexpr int kOrder = 8;

  // One step of size h from (t, x) with f = rhs(x, t): x1 = x(t + h), f1 = rhs(x1, t + h).
  // Only the first n components are computed (the rest of x1 is 0), except for small double
  // states, where all N are (components beyond n stay 0), as in dopri5::Stepper.
  // stage_inputs: the components the right-hand side reads (bit i for component i), when the
  // caller knows: the others (quadratures such as the contact's work, or the time in the u
  // phases) are only summed for x1 and the error, not for every stage's input. Used for small
  // double states with 3 active components (the ball alone: y, y', work), where it saves a
  // third to two thirds of the stages' arithmetic; the values are the same.
  template <class Sys>
  void Step(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
            State& f1, size_t n_active, unsigned stage_inputs = ~0u) {
    stage_mask_ = ~0u;
    if constexpr (kFixedWidth) {
      if (N > 3 && n_active <= 3) {
        const unsigned mask = stage_inputs & 0b111u;
        if (mask == 0b011u || mask == 0b010u) stage_mask_ = mask;
        if (mask == 0b011u) return StepWidth<3, 0b011u>(sys, x, f, t, h, x1, f1);
        if (mask == 0b010u) return StepWidth<3, 0b010u>(sys, x, f, t, h, x1, f1);
        return StepWidth<3, ~0u>(sys, x, f, t, h, x1, f1);
      }
      return StepWidth<N, ~0u>(sys, x, f, t, h, x1, f1);
    } else {
      StepWidth<0, ~0u>(sys, x, f, t, h, x1, f1, n_active);
    }
  }

  // Step over the first W components (W = 0: the first n_active).
  template <size_t W, unsigned kMask, class Sys>
  void StepWidth(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
                 State& f1, size_t n_active = W) {
    const size_t n = W > 0 ? W : n_active;
    StagePointers<T, N> k = Pointers(f, f1);
    State tmp{};
    Stage<1, kMask>(sys, x, t, h, k, tmp, n);
    Stage<2, kMask>(sys, x, t, h, k, tmp, n);
    Stage<3, kMask>(sys, x, t, h, k, tmp, n);
    Stage<4, kMask>(sys, x, t, h, k, tmp, n);
    Stage<5, kMask>(sys, x, t, h, k, tmp, n);
    Stage<6, kMask>(sys, x, t, h, k, tmp, n);
    Stage<7, kMask>(sys, x, t, h, k, tmp, n);
    Stage<8, kMask>(sys, x, t, h, k, tmp, n);
    Stage<9, kMask>(sys, x, t, h, k, tmp, n);
    Stage<10, kMask>(sys, x, t, h, k, tmp, n);
    Stage<11, kMask>(sys, x, t, h, k, tmp, n);
    for (size_t i = n; i < N; ++i) x1[i] = x[i];  // inactive: 0 and constant
    RowSum<kB>(x, h, k, x1, n);
    sys(x1, f1, t + h);
    h_ = h;
    for (size_t i = 0; i < n; ++i) {
      err5_[i] = RowValue<kE5>(k, i, std::make_index_sequence<kStages>{});
      err3_[i] = RowValue<kE3>(k, i, std::make_index_sequence<kStages>{});
    }
    dense_ready_ = false;
  }

  // The error of the last step in the norm with per-component scales sk (atol + rtol size):
  // <= 1 accepts the step.
  double ErrorNorm(const std::array<double, N>& sk, size_t n) const {
    const dopri5::ErrorSquared e = SquaredError(sk, n);
    return std::sqrt(e.num / e.den);
  }
  // Its square, h^2 e5^2 / (n deno) as num / den.
  dopri5::ErrorSquared SquaredError(const std::array<double, N>& sk, size_t n) const {
    double e5 = 0.0, e3 = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double r5 = err5_[i] / sk[i], r3 = err3_[i] / sk[i];
      e5 += r5 * r5;
      e3 += r3 * r3;
    }
    double deno = e5 + 0.01 * e3;
    if (!(deno > 0.0)) deno = 1.0;
    const double he5 = h_ * e5;
    return {he5 * he5, static_cast<double>(n) * deno};
  }

  // The continuous extension of the last Step (x -> x1 over h from t, derivatives f, f1) at
  // theta = (t' - t) / h in [0, 1]. The first call after a Step evaluates its three extra
  // stages.
  template <class Sys>
  void Dense(const Sys& sys, double t, double theta, const State& x, const State& x1,
             const State& f, const State& f1, double h, State& out, size_t n_active) {
    const size_t n = Width(n_active);
    if (!dense_ready_) Prepare(sys, t, x, x1, f, f1, h, n);
    const double theta1 = 1.0 - theta;
    out = State{};
    for (size_t i = 0; i < n; ++i) {
      const T inner = d_[3][i] + theta * (d_[4][i] + theta1 * (d_[5][i] + theta * d_[6][i]));
      out[i] =
          x[i] + theta * (d_[0][i] + theta1 * (d_[1][i] + theta * (d_[2][i] + theta1 * inner)));
    }
  }

 private:
  template <size_t S, unsigned kMask, class Sys>
  void Stage(const Sys& sys, const State& x, double t, double h, const StagePointers<T, N>& k,
             State& tmp, size_t n) {
    RowSum<kARow<S>, kMask>(x, h, k, tmp, n);
    sys(tmp, k_[S], t + kC[S] * h);
  }

  // Dense-output coefficients (HNW §II.10; Hairer's CONTD8 layout): d0 = x1 - x,
  // d1 = h f - d0, d2 = d0 - h f1 - d1, d3..d6 = h sum_j D_r,j k_j with the extra stages
  // 14..16 (at t + 0.1 h, 0.2 h, 7/9 h).
  template <class Sys>
  void Prepare(const Sys& sys, double t, const State& x, const State& x1, const State& f,
               const State& f1, double h, size_t n) {
    StagePointers<T, N> k = Pointers(f, f1);
    State tmp{};
    if (stage_mask_ == 0b011u) {
      ExtraStages<0b011u>(sys, x, t, h, k, tmp, n);
    } else if (stage_mask_ == 0b010u) {
      ExtraStages<0b010u>(sys, x, t, h, k, tmp, n);
    } else {
      ExtraStages<~0u>(sys, x, t, h, k, tmp, n);
    }
    const State zero{};
    RowSum<kDRow<0>>(zero, h, k, d_[3], n);
    RowSum<kDRow<1>>(zero, h, k, d_[4], n);
    RowSum<kDRow<2>>(zero, h, k, d_[5], n);
    RowSum<kDRow<3>>(zero, h, k, d_[6], n);
    for (size_t i = 0; i < n; ++i) {
      d_[0][i] = x1[i] - x[i];
      d_[1][i] = h * f[i] - d_[0][i];
      d_[2][i] = d_[0][i] - h * f1[i] - d_[1][i];
    }
    dense_ready_ = true;
  }

  template <unsigned kMask, class Sys>
  void ExtraStages(const Sys& sys, const State& x, double t, double h, const StagePointers<T, N>& k,
                   State& tmp, size_t n) {
    Stage<13, kMask>(sys, x, t, h, k, tmp, n);
    Stage<14, kMask>(sys, x, t, h, k, tmp, n);
    Stage<15, kMask>(sys, x, t, h, k, tmp, n);
  }

  StagePointers<T, N> Pointers(const State& f, const State& f1) const {
    StagePointers<T, N> k{};
    for (size_t s = 0; s < kStages; ++s) k[s] = &k_[s];
    k[0] = &f;
    k[kEnd] = &f1;
    return k;
  }

  static constexpr bool kFixedWidth = std::is_same_v<T, double> && N <= 4;
  static size_t Width(size_t n_active) { return kFixedWidth ? N : n_active; }

  std::array<State, kStages> k_{};  // k_[0], k_[12] unused (f and f1 are the caller's)
  std::array<State, 7> d_{};
  std::array<double, N> err5_{}, err3_{};
  double h_ = 0.0;
  unsigned stage_mask_ = ~0u;  // the stage inputs the last Step computed
  bool dense_ready_ = false;
};

// Step-size control for DOP853 (HNW §II.10 and §IV.2; the code's safety 0.9 and step ratio in
// [1/3, 6], no growth right after a rejection): dopri5's PI controller for order 8.
using Controller = dopri5::PiController<8, 3, 6>;

// The method as the contact integrator sees it.
struct Method {
  template <class T, size_t N>
  using Stepper = dop853::Stepper<T, N>;
  using Controller = dop853::Controller;
  static constexpr int kOrder = 8;
};

}  // namespace bouncecal::dop853

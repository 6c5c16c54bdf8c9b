// smg::accel_windows (energy/accel.hpp): smoothness (E21) on trajectory-major windows
// x [G][T][B][3] equals accel() on the same trajectories copied to [T][G·B][3] — the gradient bit
// for bit (moved back to the windows' layout), the energy to round-off — for each form and
// penalty, float and double; bit-identical for 1, 2 and 4 threads; degenerate shapes; a NaN
// refused naming its window, frame and trajectory.
#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "smg/energy/accel.hpp"

namespace accel_windows_test {

using smg::Index;

template <class S>
std::vector<S> windows(Index G, Index T, Index B, unsigned seed) {
  std::mt19937 g(seed);
  std::normal_distribution<double> n(0, 1);
  std::vector<S> x(std::size_t(G * T * B * 3));
  for (auto& v : x) v = S(n(g));
  return x;
}

// [G][T][B][3] -> [T][G·B][3] (trajectory (g, b) is node g·B + b).
template <class S>
std::vector<S> frame_major(const std::vector<S>& x, Index G, Index T, Index B) {
  std::vector<S> y(x.size());
  for (Index g = 0; g < G; ++g)
    for (Index t = 0; t < T; ++t)
      for (Index b = 0; b < B; ++b)
        for (int d = 0; d < 3; ++d) y[std::size_t(((t * G + g) * B + b) * 3 + d)] = x[std::size_t(((g * T + t) * B + b) * 3 + d)];
  return y;
}

template <class S>
void check_against_accel(Index G, Index T, Index B, const smg::AccelOptions& o) {
  const auto x = windows<S>(G, T, B, unsigned(G * 7 + T * 3 + B));
  std::vector<S> gw(x.size(), S(0)), gf(x.size(), S(0));
  REQUIRE(smg::validate_accel_windows<S>(x.data(), G, T, B, o).is_ok());
  const double ew = double(smg::accel_windows<S>(x.data(), G, T, B, o, gw.data()));
  const auto y = frame_major(x, G, T, B);
  const smg::PositionsView<const S> yv(y.data(), T, G * B);
  const double ef = double(smg::accel<S>(yv, {}, o, smg::PositionsView<S>(gf.data(), T, G * B)));
  CHECK(ew == doctest::Approx(ef).epsilon(sizeof(S) == 4 ? 1e-6 : 1e-14));
  const auto back = frame_major(gw, G, T, B);  // the windows' gradient in frame-major order
  const bool same_bits = std::memcmp(back.data(), gf.data(), gf.size() * sizeof(S)) == 0;
  CHECK(same_bits);
}

}  // namespace accel_windows_test

TEST_CASE_TEMPLATE("accel_windows: accel() on the trajectories, without the layout copy", S, float, double) {
  using namespace accel_windows_test;
  for (smg::AccelForm form : {smg::AccelForm::acceleration, smg::AccelForm::velocity})
    for (smg::Penalty p : {smg::Penalty::squared, smg::Penalty::norm, smg::Penalty::sqrt_weighted})
      for (smg::Normalization nz : {smg::Normalization::sum, smg::Normalization::mean}) {
        smg::AccelOptions o;
        o.form = form;
        o.penalty = p;
        o.normalization = nz;
        o.weight = 0.7;
        CAPTURE(int(form));
        CAPTURE(int(p));
        check_against_accel<S>(300, 3, 8, o);  // Shape of Motion's trainer tracks [G, 3, B, 3]
        check_against_accel<S>(40, 30, 1, o);  // its motion bases / initial tracks [K, T, 3]
        check_against_accel<S>(1, 5, 700, o);
      }
}

TEST_CASE("accel_windows: the same bits on 1, 2 and 4 threads; degenerate shapes; a NaN refused") {
  using namespace accel_windows_test;
  smg::AccelOptions o;
  o.penalty = smg::Penalty::norm;
  o.normalization = smg::Normalization::mean;
  const Index G = 5000, T = 3, B = 8;
  const auto x = windows<float>(G, T, B, 9);
  std::vector<std::vector<float>> grads;
  std::vector<double> energies;
  for (int threads : {1, 2, 4}) {
    smg::ParallelOptions p;
    p.threads = threads;
    grads.emplace_back(x.size(), 0.0f);
    energies.push_back(double(smg::accel_windows<float>(x.data(), G, T, B, o, grads.back().data(), p)));
  }
  CHECK(energies[1] == energies[0]);
  CHECK(energies[2] == energies[0]);
  CHECK(grads[1] == grads[0]);
  CHECK(grads[2] == grads[0]);
  // Fewer frames than the form spans: no terms, energy 0, gradient untouched.
  std::vector<float> g2(std::size_t(4 * 2 * 3 * 3), 0.0f);
  CHECK(double(smg::accel_windows<float>(x.data(), 4, 2, 3, o, g2.data())) == 0.0);
  CHECK(g2 == std::vector<float>(g2.size(), 0.0f));
  CHECK(double(smg::accel_windows<float>(nullptr, 0, 3, 8, o)) == 0.0);
  auto bad = x;
  bad[std::size_t(((7 * T + 2) * B + 5) * 3 + 1)] = std::numeric_limits<float>::quiet_NaN();
  CHECK(smg::validate_accel_windows<float>(bad.data(), G, T, B, o).message() ==
        "positions: window 7, frame 2, trajectory 5 has a NaN or infinite coordinate");
  o.weight = std::numeric_limits<double>::infinity();
  CHECK_FALSE(smg::validate_accel_windows<float>(x.data(), G, T, B, o).is_ok());
}

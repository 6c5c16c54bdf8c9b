// The known volume loss of linear blend skinning on a twisting pair, against DQB.
//
// Two nodes on the x axis, at x = −1 and x = +1; between t_ref = 0 and t = 1 the node at +1
// twists by θ about the x axis (its own axis), the other stays. A closed tube of radius ρ around
// the axis is skinned by both nodes (weights from skinning_weights). Every node motion is a
// rotation about the x axis, so DQB maps each surface point to a rotation of it about the axis
// by the blended angle: radii are preserved exactly. LBS averages the rotated points instead:
// a point with weights (w0, w1) lands at radius ρ |w0 + w1 e^{iθ}| — the "candy wrapper".
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "skin/skin_test_support.hpp"
#include "support/prelude.hpp"

namespace {
constexpr double kPi = 3.14159265358979323846;

struct Tube {
  int rings = 81, sectors = 64;
  double radius = 0.3;
  std::vector<double> points;  // [rings * sectors][3], ring-major, rings at x in [-1, 1]
  double x(int i) const { return -1 + 2.0 * i / (rings - 1); }
};

Tube make_tube() {
  Tube t;
  for (int i = 0; i < t.rings; ++i)
    for (int j = 0; j < t.sectors; ++j) {
      const double a = 2 * kPi * j / t.sectors;
      t.points.insert(t.points.end(), {t.x(i), t.radius * std::cos(a), t.radius * std::sin(a)});
    }
  return t;
}

// Volume by slices (Cavalieri): every ring stays in its plane x = const (checked), so the
// solid's cross-section there is the ring's polygon (shoelace area in the yz plane); the
// volume is the trapezoidal integral of the areas over x. A triangulated surface would not do:
// LBS twists neighbouring rings by more than a sector near the middle and folds the faces.
double volume(const Tube& t, const std::vector<double>& x) {
  std::vector<double> area(static_cast<std::size_t>(t.rings), 0.0);
  for (int i = 0; i < t.rings; ++i)
    for (int j = 0; j < t.sectors; ++j) {
      const double* a = &x[(i * t.sectors + j) * 3];
      const double* b = &x[(i * t.sectors + (j + 1) % t.sectors) * 3];
      area[i] += 0.5 * (a[1] * b[2] - a[2] * b[1]);
    }
  double v = 0;
  for (int i = 0; i + 1 < t.rings; ++i) v += 0.5 * (area[i] + area[i + 1]) * (t.x(i + 1) - t.x(i));
  return v;
}

struct TwistResult {
  double volume_ratio_dqb, volume_ratio_lbs, max_radius_error_dqb, max_radius_error_lbs_formula,
      min_radius_lbs, max_axial_motion;
};

TwistResult twist(double theta, double sigma) {
  const Tube tube = make_tube();
  const Index P = Index(tube.points.size() / 3), N = 2, T = 2;
  const std::vector<double> positions = {-1, 0, 0, 1, 0, 0, -1, 0, 0, 1, 0, 0};
  const smg::Quaternion<double> r = smg::so3::exp(Vector3<double>(theta, 0, 0));
  const std::vector<double> quats = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, r.w(), r.x(), r.y(), r.z()};
  const std::vector<std::int32_t> gi = {1, 0};
  const std::vector<double> gw = {1, 1}, sig = {sigma, sigma};
  std::vector<std::int32_t> anchor(P), t_ref(P, 0), drivers(P * 2), tq = {1};
  for (Index p = 0; p < P; ++p) anchor[p] = tube.points[p * 3] < 0 ? 0 : 1;
  smg::skin_drivers(smg::NeighborsView<double>(gi.data(), gw.data(), N, 1), {anchor.data(), P},
                    {drivers.data(), P, 2});
  std::vector<double> w(P * 2);
  smg::skinning_weights<double>({positions.data(), T, N}, {drivers.data(), P, 2}, {t_ref.data(), P},
                                {tube.points.data(), P}, {sig.data(), N}, {w.data(), P, 2});
  smg::SkinPoints<double> pts;
  pts.drivers = {drivers.data(), P, 2};
  pts.weights = {w.data(), P, 2};
  pts.t_ref = {t_ref.data(), P};
  pts.positions = {tube.points.data(), P};
  const smg::SkinNodes<double> nodes{{positions.data(), T, N}, {quats.data(), T, N}};
  TwistResult res{};
  const double v0 = volume(tube, tube.points);
  res.min_radius_lbs = 1e300;
  for (smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
    std::vector<double> out(P * 3);
    smg::SkinBlendOutputs<double> o;
    o.positions = {out.data(), 1, P};
    smg::SkinOptions opt;
    opt.method = m;
    smg::skin_blend(nodes, pts, {tq.data(), 1}, o, opt);
    const double ratio = volume(tube, out) / v0;
    for (Index p = 0; p < P; ++p) {
      const double rad = Vector3<double>(0, out[p * 3 + 1], out[p * 3 + 2]).norm();
      res.max_axial_motion = std::max(res.max_axial_motion, std::abs(out[p * 3] - tube.points[p * 3]));
      if (m == smg::SkinMethod::dqb) {
        res.max_radius_error_dqb = std::max(res.max_radius_error_dqb, std::abs(rad - tube.radius));
      } else {
        const double w0 = w[p * 2 + (anchor[p] == 0 ? 0 : 1)];  // weight of node 0
        const double w1 = 1 - w0;
        const double expect = tube.radius * std::sqrt(w0 * w0 + w1 * w1 + 2 * w0 * w1 * std::cos(theta));
        res.max_radius_error_lbs_formula = std::max(res.max_radius_error_lbs_formula, std::abs(rad - expect));
        res.min_radius_lbs = std::min(res.min_radius_lbs, rad);
      }
    }
    (m == smg::SkinMethod::dqb ? res.volume_ratio_dqb : res.volume_ratio_lbs) = ratio;
  }
  return res;
}
}  // namespace

TEST_CASE("twisting pair: LBS loses volume (candy wrapper), DQB preserves radii exactly") {
  for (double degrees : {30.0, 90.0, 150.0, 179.0}) {
    const TwistResult r = twist(degrees * kPi / 180, 0.6);
    MESSAGE("twist ", degrees, " deg: volume ratio DQB ", r.volume_ratio_dqb, ", LBS ",
            r.volume_ratio_lbs, ", thinnest LBS radius ", r.min_radius_lbs, " of 0.3");
    CHECK(r.max_axial_motion < 1e-14);  // rings stay in their planes (slices are exact)
    CHECK(r.max_radius_error_dqb < 1e-14);
    CHECK(r.max_radius_error_lbs_formula < 1e-14);
    CHECK(std::abs(r.volume_ratio_dqb - 1) < 1e-14);
    // LBS: the mid-section shrinks towards the axis, by cos(θ/2) at equal weights.
    CHECK(r.volume_ratio_lbs < r.volume_ratio_dqb);
    CHECK(r.min_radius_lbs < 0.3 * std::cos(degrees * kPi / 360) + 1e-3);
  }
}

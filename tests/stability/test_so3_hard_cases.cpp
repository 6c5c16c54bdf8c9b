// Hard cases for the core rotation and rigid-motion maths. Each case states the defined
// behaviour (docs/conventions.md, "Hard cases").
#include <doctest/doctest.h>

#include <cmath>
#include <limits>

#include "smg/core/dual_quaternion.hpp"
#include "smg/core/so3.hpp"
#include "support/prelude.hpp"

TEST_CASE("near-pi rotations: Log is accurate and the inverse right Jacobian stays finite") {
  SMG_TEST_RNG(rng, 41);
  for (double eps : {1e-3, 1e-6, 1e-9, 1e-12, 0.0}) {
    CAPTURE(eps);
    const Vector3<double> axis = rng.unit3();
    const Vector3<double> phi = (M_PI - eps) * axis;
    const Quaternion<double> q = smg::so3::exp(phi);
    const Vector3<double> back = smg::so3::log(q);
    // At exactly pi both +pi n and -pi n are correct; rounding of |phi| picks one.
    CHECK(std::min((back - phi).norm(), eps == 0.0 ? (back + phi).norm() : 1.0) < 1e-14);
    const Matrix3<double> Jinv = smg::so3::right_jacobian_inverse(back);
    CHECK(Jinv.allFinite());
    CHECK((Jinv * smg::so3::right_jacobian(back) - Matrix3<double>::Identity()).norm() < 1e-12);
  }
}

TEST_CASE("antipodal quaternions: q and -q are the same rotation everywhere") {
  SMG_TEST_RNG(rng, 42);
  for (int k = 0; k < 50; ++k) {
    const Quaternion<double> q = rng.quaternion();
    const Quaternion<double> mq(-q.coeffs());
    const Vector3<double> v = rng.vec3(2);
    CHECK((smg::so3::rotate(q, v) - smg::so3::rotate(mq, v)).norm() < 1e-14);
    CHECK(smg::so3::angular_distance(q, mq) < 1e-7);  // acos-free: exact up to rounding
    const auto a = smg::dual_quaternion_from_rotation_translation(q, v);
    const auto b = smg::dual_quaternion_from_rotation_translation(mq, v);
    const Vector3<double> p = rng.vec3(1);
    CHECK((smg::dual_quaternion_transform_point(a, p) - smg::dual_quaternion_transform_point(b, p))
              .norm() < 1e-14);
  }
}

TEST_CASE("tiny and subnormal rotation vectors: finite, exact to first order") {
  for (double angle : {1e-300, 1e-200, 1e-30, 4.9e-324}) {
    CAPTURE(angle);
    const Vector3<double> phi(angle, 0, 0);
    Matrix3<double> J;
    const Quaternion<double> q = smg::so3::exp(phi, &J);
    CHECK(q.w() == 1.0);
    CHECK(q.x() == angle / 2);
    CHECK((J - Matrix3<double>::Identity()).norm() < 1e-15);
    CHECK((smg::so3::log(q) - phi).norm() <= std::numeric_limits<double>::denorm_min());
  }
}

TEST_CASE("angles beyond pi: Exp is 2pi-periodic up to sign and Log wraps into [0, pi]") {
  const Vector3<double> axis = Vector3<double>(0.2, -0.4, 0.8).normalized();
  for (double angle : {M_PI + 0.5, 2 * M_PI - 0.1, 3 * M_PI + 0.2, 100.0}) {
    CAPTURE(angle);
    const Quaternion<double> q = smg::so3::exp(Vector3<double>(angle * axis));
    const Vector3<double> back = smg::so3::log(q);
    CHECK(back.norm() <= M_PI + 1e-14);
    const Quaternion<double> q2 = smg::so3::exp(back);
    CHECK(std::min((q.coeffs() - q2.coeffs()).norm(), (q.coeffs() + q2.coeffs()).norm()) < 1e-13);
  }
}

TEST_CASE("huge and tiny translations in dual quaternions") {
  SMG_TEST_RNG(rng, 43);
  for (double scale : {1e-9, 1.0, 1e6, 1e12}) {
    CAPTURE(scale);
    const Quaternion<double> q = rng.quaternion();
    const Vector3<double> t = rng.vec3(scale), p = rng.vec3(scale);
    const auto d = smg::dual_quaternion_from_rotation_translation(q, t);
    const Vector3<double> y = smg::dual_quaternion_transform_point(d, p);
    CHECK((y - (q * p + t)).norm() <= 1e-14 * scale * 10);
  }
}

TEST_CASE("float Exp/Log near pi and near 0 stay finite and accurate to float rounding") {
  const Vector3<float> axis = Vector3<float>(1, 1, -1).normalized();
  for (float angle : {0.0f, 1e-30f, 1e-6f, 3.14159f, static_cast<float>(M_PI)}) {
    CAPTURE(angle);
    const Quaternion<float> q = smg::so3::exp(Vector3<float>(angle * axis));
    const Vector3<float> back = smg::so3::log(q);
    CHECK(back.allFinite());
    CHECK((back - angle * axis).norm() <= 1e-6f * std::max(1.0f, angle));
    CHECK(smg::so3::right_jacobian_inverse(back).allFinite());
  }
}

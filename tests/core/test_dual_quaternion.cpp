// Tests of smg/core/dual_quaternion.hpp: rigid-motion semantics, and every Jacobian against
// central finite differences (double) and AutoDiffScalar; float against double.
#include <doctest/doctest.h>

#include "smg/core/dual_quaternion.hpp"
#include "smg/core/so3.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

using smg::DualQuaternion;

namespace {
using DQ = DualQuaternion<double>;
DQ from8(const VectorXd& c) { return DQ::from_coeffs_wxyz(Vector8<double>(c)); }
DQ random_motion(smg::test::Rng& rng, double t_scale = 2.0) {
  return smg::dual_quaternion_from_rotation_translation(rng.quaternion(), rng.vec3(t_scale));
}
}  // namespace

TEST_CASE("dual quaternion of (R, t) applies R p + t and round-trips") {
  SMG_TEST_RNG(rng, 21);
  for (int k = 0; k < 50; ++k) {
    const Quaternion<double> q = rng.quaternion();
    const Vector3<double> t = rng.vec3(10), p = rng.vec3(3);
    const DQ d = smg::dual_quaternion_from_rotation_translation(q, t);
    // Unit: |r| = 1 and r·s = 0.
    CHECK(std::abs(d.real.norm() - 1) < 1e-15);
    CHECK(std::abs(d.real.coeffs().dot(d.dual.coeffs())) < 1e-14);
    CHECK((smg::dual_quaternion_transform_point(d, p) - (q * p + t)).norm() < 1e-13);
    Quaternion<double> q2;
    Vector3<double> t2;
    smg::dual_quaternion_to_rotation_translation(d, &q2, &t2);
    CHECK((q2.coeffs() - q.coeffs()).norm() < 1e-15);
    CHECK((t2 - t).norm() < 1e-13);
    // A scaled (non-unit) dual quaternion represents the same motion.
    const DQ scaled = DQ::from_coeffs_wxyz(3.7 * d.coeffs_wxyz());
    CHECK((smg::dual_quaternion_transform_point(scaled, p) - (q * p + t)).norm() < 1e-13);
    // -d is the same motion (double cover).
    const DQ neg = DQ::from_coeffs_wxyz(-d.coeffs_wxyz());
    CHECK((smg::dual_quaternion_transform_point(neg, p) - (q * p + t)).norm() < 1e-13);
  }
}

TEST_CASE("product composes motions, conjugate inverts, normalisation makes |r| = 1") {
  SMG_TEST_RNG(rng, 22);
  for (int k = 0; k < 50; ++k) {
    const DQ a = random_motion(rng), b = random_motion(rng);
    const Vector3<double> p = rng.vec3(3);
    const DQ ab = smg::dual_quaternion_product(a, b);
    const Vector3<double> expected =
        smg::dual_quaternion_transform_point(a, smg::dual_quaternion_transform_point(b, p));
    CHECK((smg::dual_quaternion_transform_point(ab, p) - expected).norm() < 1e-13);
    const DQ ai = smg::dual_quaternion_conjugate(a);
    CHECK((smg::dual_quaternion_transform_point(ai, smg::dual_quaternion_transform_point(a, p)) - p)
              .norm() < 1e-13);
    const DQ s = DQ::from_coeffs_wxyz(0.3 * a.coeffs_wxyz() + 0.7 * b.coeffs_wxyz());
    const DQ n = smg::dual_quaternion_normalized(s);
    CHECK(std::abs(n.real.norm() - 1) < 1e-15);
  }
}

TEST_CASE("dual quaternion Jacobians against central differences") {
  SMG_TEST_RNG(rng, 23);
  for (int trial = 0; trial < 20; ++trial) {
    const Quaternion<double> q = rng.quaternion();
    const Vector3<double> t = rng.vec3(4);
    smg::Matrix83<double> Jq, Jt;
    smg::dual_quaternion_from_rotation_translation(q, t, &Jq, &Jt);
    CHECK(relative_error(Jq, central_jacobian([&](const VectorXd& d) -> VectorXd {
                           return smg::dual_quaternion_from_rotation_translation(
                                      Quaternion<double>(q * smg::so3::exp(Vector3<double>(d))), t)
                               .coeffs_wxyz();
                         }, VectorXd::Zero(3))) < 1e-8);
    CHECK(relative_error(Jt, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_from_rotation_translation(q, Vector3<double>(x))
                               .coeffs_wxyz();
                         }, VectorXd(t))) < 1e-8);

    // Product, conjugate, normalisation and transform on generic (non-unit) 8-vectors: the raw
    // Jacobians must hold off the unit manifold too, since DQB blends before normalising.
    const VectorXd a = VectorXd::Random(8) + random_motion(rng).coeffs_wxyz();
    const VectorXd b = VectorXd::Random(8) + random_motion(rng).coeffs_wxyz();
    smg::Matrix8<double> Ja, Jb, Jc, Jn;
    smg::dual_quaternion_product(from8(a), from8(b), &Ja, &Jb);
    CHECK(relative_error(Ja, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_product(from8(x), from8(b)).coeffs_wxyz();
                         }, a)) < 1e-9);
    CHECK(relative_error(Jb, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_product(from8(a), from8(x)).coeffs_wxyz();
                         }, b)) < 1e-9);
    smg::dual_quaternion_conjugate(from8(a), &Jc);
    CHECK(relative_error(Jc, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_conjugate(from8(x)).coeffs_wxyz();
                         }, a)) < 1e-9);
    smg::dual_quaternion_normalized(from8(a), &Jn);
    CHECK(relative_error(Jn, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_normalized(from8(x)).coeffs_wxyz();
                         }, a)) < 1e-8);
    const Vector3<double> p = rng.vec3(3);
    smg::Matrix38<double> Jd;
    Matrix3<double> Jp;
    smg::dual_quaternion_transform_point(from8(a), p, &Jd, &Jp);
    CHECK(relative_error(Jd, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_transform_point(from8(x), p);
                         }, a)) < 1e-8);
    CHECK(relative_error(Jp, central_jacobian([&](const VectorXd& x) -> VectorXd {
                           return smg::dual_quaternion_transform_point(from8(a), Vector3<double>(x));
                         }, VectorXd(p))) < 1e-8);
  }
}

TEST_CASE("AutoDiffScalar cross-check: transform_point and product") {
  using smg::test::AD;
  SMG_TEST_RNG(rng, 24);
  for (int trial = 0; trial < 5; ++trial) {
    const Vector8<double> a = random_motion(rng).coeffs_wxyz() + 0.1 * Vector8<double>::Random();
    const Vector8<double> b = random_motion(rng).coeffs_wxyz();
    const Vector3<double> p = rng.vec3(2);
    const auto a_ad = smg::test::ad_variables<8>(a, 11, 0);
    const auto p_ad = smg::test::ad_variables<3>(p, 11, 8);
    const Vector3<AD> y = smg::dual_quaternion_transform_point(
        DualQuaternion<AD>::from_coeffs_wxyz(a_ad), p_ad);
    smg::Matrix38<double> Jd;
    Matrix3<double> Jp;
    smg::dual_quaternion_transform_point(DQ::from_coeffs_wxyz(a), p, &Jd, &Jp);
    const MatrixXd J = smg::test::ad_jacobian<3>(y, 11);
    CHECK(relative_error(J.leftCols(8), Jd) < 1e-12);
    CHECK(relative_error(J.rightCols(3), Jp) < 1e-12);

    const auto a16 = smg::test::ad_variables<8>(a, 16, 0);
    const auto b16 = smg::test::ad_variables<8>(b, 16, 8);
    const Vector8<AD> ab = smg::dual_quaternion_product(DualQuaternion<AD>::from_coeffs_wxyz(a16),
                                                        DualQuaternion<AD>::from_coeffs_wxyz(b16))
                               .coeffs_wxyz();
    smg::Matrix8<double> Ja, Jb;
    smg::dual_quaternion_product(DQ::from_coeffs_wxyz(a), DQ::from_coeffs_wxyz(b), &Ja, &Jb);
    const MatrixXd Jab = smg::test::ad_jacobian<8>(ab, 16);
    CHECK(relative_error(Jab.leftCols(8), Ja) < 1e-14);
    CHECK(relative_error(Jab.rightCols(8), Jb) < 1e-14);
  }
}

TEST_CASE("float against double: dual quaternion transform and Jacobians") {
  SMG_TEST_RNG(rng, 25);
  for (int trial = 0; trial < 20; ++trial) {
    const DQ d = random_motion(rng, 5);
    const Vector3<double> p = rng.vec3(3);
    const DualQuaternion<float> df = DualQuaternion<float>::from_coeffs_wxyz(d.coeffs_wxyz().cast<float>());
    smg::Matrix38<double> Jd;
    smg::Matrix38<float> Jf;
    const Vector3<double> yd = smg::dual_quaternion_transform_point(d, p, &Jd);
    const Vector3<float> yf = smg::dual_quaternion_transform_point(df, Vector3<float>(p.cast<float>()), &Jf);
    CHECK(relative_error(yf, yd) < 1e-6);
    CHECK(relative_error(Jf, Jd) < 1e-6);
  }
}

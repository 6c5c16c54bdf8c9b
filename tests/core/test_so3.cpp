// Tests of smg/core/so3.hpp: hat/vee, Exp/Log round trips, right Jacobians and the Jacobians of
// rotate / inverse_rotate / compose / inverse / between, against central finite differences
// (double) and Eigen's AutoDiffScalar; float against double.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "smg/core/so3.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

namespace {

Quaternion<double> perturb_right(const Quaternion<double>& q, const Eigen::VectorXd& d) {
  return q * smg::so3::exp(Vector3<double>(d.head<3>()));
}
// The right-tangent difference Log(a^-1 b) as a VectorXd.
VectorXd tangent_diff(const Quaternion<double>& a, const Quaternion<double>& b) {
  return smg::so3::log(Quaternion<double>(a.conjugate() * b));
}

// Angles for finite-difference checks. They stay 1e-4 below pi: a perturbation of size h = 1e-6
// across pi would make Log jump to the other branch. Closer to pi, Jacobians are checked by
// AutoDiffScalar and by Jr^-1 Jr = I (stability/test_so3_hard_cases.cpp).
const std::vector<double> kAngles = {0.0, 1e-12, 1e-6, 1e-3, 0.0999, 0.1001, 0.3, 0.9, 1.0, 2.0, 3.0,
                                     M_PI - 1e-4};

}  // namespace

TEST_CASE("hat and vee") {
  SMG_TEST_RNG(rng, 11);
  for (int k = 0; k < 20; ++k) {
    const Vector3<double> v = rng.vec3(3), u = rng.vec3(2);
    const Matrix3<double> H = smg::so3::hat(v);
    CHECK((H * u - v.cross(u)).norm() < 1e-14);
    CHECK((H + H.transpose()).norm() == 0.0);
    CHECK((smg::so3::vee(H) - v).norm() == 0.0);
  }
}

TEST_CASE("Exp/Log round trips at 0, 1e-12, 1e-6, 1, pi - 1e-9 and pi") {
  SMG_TEST_RNG(rng, 12);
  for (double angle : {0.0, 1e-12, 1e-6, 1.0, M_PI - 1e-9, M_PI}) {
    for (int k = 0; k < 10; ++k) {
      CAPTURE(angle);
      const Vector3<double> axis = rng.unit3();
      const Vector3<double> phi = angle * axis;
      const Quaternion<double> q = smg::so3::exp(phi);
      CHECK(std::abs(q.norm() - 1.0) < 1e-15);
      const Vector3<double> back = smg::so3::log(q);
      // Absolute error relative to max(angle, tiny): the round trip is accurate to rounding at
      // every angle, including the series branches. At exactly pi, +pi n and -pi n are the same
      // rotation and rounding in |phi| picks either (documented), so both are accepted there.
      const double err = angle == M_PI ? std::min((back - phi).norm(), (back + phi).norm())
                                       : (back - phi).norm();
      CHECK(err <= 4e-16 * std::max(angle, 1e-300) + 1e-300);
      // Exp(Log(q)) gives q back up to sign.
      const Quaternion<double> q2 = smg::so3::exp(back);
      CHECK(std::min((q2.coeffs() - q.coeffs()).norm(), (q2.coeffs() + q.coeffs()).norm()) < 1e-15);
    }
  }
}

TEST_CASE("Log is the same for q and -q, and picks the angle in [0, pi]") {
  SMG_TEST_RNG(rng, 13);
  for (int k = 0; k < 100; ++k) {
    const Quaternion<double> q = rng.quaternion();
    const Quaternion<double> mq(-q.coeffs());
    const Vector3<double> a = smg::so3::log(q), b = smg::so3::log(mq);
    CHECK((a - b).norm() < 1e-15);
    CHECK(a.norm() <= M_PI + 1e-15);
  }
  // Exactly pi: w = 0, so the sign of the vector part chooses between +pi n and -pi n (both
  // correct); the angle is pi either way.
  const Quaternion<double> half_turn(0.0, 0.0, 0.0, 1.0);
  CHECK(std::abs(smg::so3::log(half_turn).norm() - M_PI) < 1e-15);
  CHECK(std::abs(smg::so3::log(Quaternion<double>(-half_turn.coeffs())).norm() - M_PI) < 1e-15);
}

TEST_CASE("Log does not need a unit quaternion") {
  SMG_TEST_RNG(rng, 14);
  for (double scale : {1e-8, 0.5, 3.0, 1e8}) {
    const Quaternion<double> q = rng.quaternion();
    CHECK((smg::so3::log(Quaternion<double>(scale * q.coeffs())) - smg::so3::log(q)).norm() < 1e-14);
  }
}

TEST_CASE("Right Jacobian of Exp against central differences") {
  SMG_TEST_RNG(rng, 15);
  for (double angle : kAngles) {
    CAPTURE(angle);
    const Vector3<double> phi = angle * rng.unit3();
    Matrix3<double> J;
    const Quaternion<double> q = smg::so3::exp(phi, &J);
    CHECK(relative_error(J, smg::so3::right_jacobian(phi)) < 1e-15);  // shared-trig path
    // Exp(phi + d) = Exp(phi) Exp(Jr d): differentiate Log(Exp(phi)^-1 Exp(phi + d)).
    const MatrixXd fd = central_jacobian(
        [&](const VectorXd& d) { return tangent_diff(q, smg::so3::exp(Vector3<double>(phi + d))); },
        VectorXd::Zero(3));
    CHECK(relative_error(J, fd) < 1e-8);
  }
}

TEST_CASE("Jacobian of Log is the inverse right Jacobian") {
  SMG_TEST_RNG(rng, 16);
  for (double angle : kAngles) {
    CAPTURE(angle);
    const Quaternion<double> q = rng.rotation_with_angle(angle);
    Matrix3<double> J;
    const Vector3<double> phi = smg::so3::log(q, &J);
    const MatrixXd fd = central_jacobian(
        [&](const VectorXd& d) -> VectorXd { return smg::so3::log(perturb_right(q, d)); },
        VectorXd::Zero(3));
    CHECK(relative_error(J, fd) < 1e-7);
    CHECK((J * smg::so3::right_jacobian(phi) - Matrix3<double>::Identity()).norm() < 1e-12);
  }
}

TEST_CASE("Right Jacobian series and closed form agree at the switch point") {
  // Just below and above series_threshold the two branches must agree to rounding.
  // The inputs differ by a few ulps so that the comparison measures the branch switch, not the
  // (first-order) change of the function.
  const double thr = smg::series_threshold<double>();
  const Vector3<double> axis(1, 0, 0);
  const Vector3<double> lo = std::nextafter(thr, 0.0) * axis, hi = std::nextafter(thr, 1.0) * axis;
  CHECK(lo.squaredNorm() < thr * thr);
  CHECK(hi.squaredNorm() >= thr * thr);
  CHECK((smg::so3::right_jacobian(lo) - smg::so3::right_jacobian(hi)).norm() < 1e-15);
  CHECK((smg::so3::right_jacobian_inverse(lo) - smg::so3::right_jacobian_inverse(hi)).norm() < 1e-15);
  CHECK((smg::so3::exp(lo).coeffs() - smg::so3::exp(hi).coeffs()).norm() < 1e-15);
  const float thrf = smg::series_threshold<float>();
  const Vector3<float> lof(std::nextafter(thrf, 0.f), 0, 0), hif(std::nextafter(thrf, 1.f), 0, 0);
  CHECK((smg::so3::right_jacobian(lof) - smg::so3::right_jacobian(hif)).norm() < 1e-6f);
  CHECK((smg::so3::right_jacobian_inverse(lof) - smg::so3::right_jacobian_inverse(hif)).norm() < 1e-6f);
}

TEST_CASE("rotate, inverse_rotate, compose, inverse, between: Jacobians against central differences") {
  SMG_TEST_RNG(rng, 17);
  for (int trial = 0; trial < 20; ++trial) {
    const Quaternion<double> a = rng.quaternion(), b = rng.quaternion();
    const Vector3<double> v = rng.vec3(5);
    const VectorXd v0 = v;

    // R v and a ⊗ b, then (inverse) R^T v and a^-1 ⊗ b: the Jacobians in q, a and b (right
    // tangents) and in v.
    for (bool inverse : {false, true}) {
      CAPTURE(inverse);
      const auto rot = [inverse](const Quaternion<double>& q, const Vector3<double>& x, Matrix3<double>* Jq = nullptr,
                                 Matrix3<double>* Jx = nullptr) {
        return inverse ? smg::so3::inverse_rotate(q, x, Jq, Jx) : smg::so3::rotate(q, x, Jq, Jx);
      };
      Matrix3<double> Jq, Jv;
      rot(a, v, &Jq, &Jv);
      CHECK(relative_error(Jq, central_jacobian([&](const VectorXd& d) -> VectorXd {
                             return rot(perturb_right(a, d), v);
                           }, VectorXd::Zero(3))) < 1e-8);
      CHECK(relative_error(Jv, central_jacobian([&](const VectorXd& x) -> VectorXd {
                             return rot(a, Vector3<double>(x));
                           }, v0)) < 1e-8);

      const auto op = [inverse](const Quaternion<double>& x, const Quaternion<double>& y, Matrix3<double>* Jx = nullptr,
                                Matrix3<double>* Jy = nullptr) {
        return inverse ? smg::so3::between(x, y, Jx, Jy) : smg::so3::compose(x, y, Jx, Jy);
      };
      Matrix3<double> Ja, Jb;
      const Quaternion<double> out = op(a, b, &Ja, &Jb);
      CHECK(relative_error(Ja, central_jacobian([&](const VectorXd& d) {
                             return tangent_diff(out, op(perturb_right(a, d), b));
                           }, VectorXd::Zero(3))) < 1e-8);
      CHECK(relative_error(Jb, central_jacobian([&](const VectorXd& d) {
                             return tangent_diff(out, op(a, perturb_right(b, d)));
                           }, VectorXd::Zero(3))) < 1e-8);
    }

    Matrix3<double> Ja;
    const Quaternion<double> ai = smg::so3::inverse(a, &Ja);
    CHECK(relative_error(Ja, central_jacobian([&](const VectorXd& d) {
                           return tangent_diff(ai, smg::so3::inverse(perturb_right(a, d)));
                         }, VectorXd::Zero(3))) < 1e-8);
  }
}

TEST_CASE("AutoDiffScalar cross-check: Exp, Log, rotate, inverse_rotate, compose") {
  using smg::test::AD;
  SMG_TEST_RNG(rng, 18);
  for (double angle : {0.0, 1e-6, 0.7, 2.5, M_PI - 1e-6}) {
    CAPTURE(angle);
    // d to_wxyz(Exp(phi)) / d phi = quat_tangent_jacobian(Exp(phi)) * Jr(phi) (4x3).
    const Vector3<double> phi = angle * rng.unit3();
    const auto phi_ad = smg::test::ad_variables<3>(phi, 3);
    const Quaternion<AD> q_ad = smg::so3::exp(phi_ad);
    const Eigen::Matrix<AD, 4, 1> q_coeffs(q_ad.w(), q_ad.x(), q_ad.y(), q_ad.z());
    const Quaternion<double> q = smg::so3::exp(phi);
    const MatrixXd expected = smg::quat_tangent_jacobian(q) * smg::so3::right_jacobian(phi);
    CHECK(relative_error(smg::test::ad_jacobian<4>(q_coeffs, 3), expected) < 1e-12);

    // Log(q Exp(d)) at d = 0 through AD: Jr^-1(Log q).
    const auto d_ad = smg::test::ad_variables<3>(Vector3<double>::Zero(), 3);
    const Quaternion<AD> q_const(AD(q.w()), AD(q.x()), AD(q.y()), AD(q.z()));
    const Vector3<AD> log_ad = smg::so3::log(Quaternion<AD>(q_const * smg::so3::exp(d_ad)));
    Matrix3<double> J_log;
    smg::so3::log(q, &J_log);
    CHECK(relative_error(smg::test::ad_jacobian<3>(log_ad, 3), J_log) < 1e-10);

    // rotate / inverse_rotate w.r.t. (right tangent, vector): 6 AD variables.
    const Vector3<double> v = rng.vec3(2);
    const auto d6 = smg::test::ad_variables<3>(Vector3<double>::Zero(), 6, 0);
    const auto v6 = smg::test::ad_variables<3>(v, 6, 3);
    const Quaternion<AD> q6 = Quaternion<AD>(q.w(), q.x(), q.y(), q.z()) * smg::so3::exp(d6);
    Matrix3<double> Jq, Jv;
    smg::so3::rotate(q, v, &Jq, &Jv);
    MatrixXd J_rot = smg::test::ad_jacobian<3>(smg::so3::rotate(q6, v6), 6);
    CHECK(relative_error(J_rot.leftCols(3), Jq) < 1e-12);
    CHECK(relative_error(J_rot.rightCols(3), Jv) < 1e-12);
    smg::so3::inverse_rotate(q, v, &Jq, &Jv);
    J_rot = smg::test::ad_jacobian<3>(smg::so3::inverse_rotate(q6, v6), 6);
    CHECK(relative_error(J_rot.leftCols(3), Jq) < 1e-12);
    CHECK(relative_error(J_rot.rightCols(3), Jv) < 1e-12);
  }
}

TEST_CASE("float against double: Exp, Log, right Jacobians, rotate") {
  SMG_TEST_RNG(rng, 19);
  for (double angle : kAngles) {
    CAPTURE(angle);
    const Vector3<double> phi = angle * rng.unit3();
    const Vector3<float> phif = phi.cast<float>();
    const Quaternion<double> qd = smg::so3::exp(phi);
    const Quaternion<float> qf = smg::so3::exp(phif);
    CHECK((qf.coeffs().cast<double>() - qd.coeffs()).norm() < 2e-7);
    // Log in float: the absolute angle error is bounded by float rounding of the input.
    CHECK((smg::so3::log(qf).cast<double>() - smg::so3::log(qd.cast<double>())).norm() <
          4e-7 * std::max(1.0, angle));
    CHECK(relative_error(smg::so3::right_jacobian(phif), smg::so3::right_jacobian(phi)) < 1e-6);
    CHECK(relative_error(smg::so3::right_jacobian_inverse(phif),
                         smg::so3::right_jacobian_inverse(phi)) < 1e-6);
    const Vector3<double> v = rng.vec3(3);
    CHECK(relative_error(smg::so3::rotate(qf, Vector3<float>(v.cast<float>())),
                         smg::so3::rotate(qd, v)) < 1e-6);
  }
}

// Projection, rotation and spherical-harmonics building blocks against central finite
// differences in double: project_gaussian_vjp (including gsplat's field-of-view clamp of the
// Jacobian), rotmat_from_unit_wxyz_vjp, sh_basis derivatives and sh_to_color_vjp.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "splat_scene.hpp"
#include "support/finite_diff.hpp"

using namespace smg;
using namespace smg::splat;

namespace {

// y = (mean2d, conic, depth) of a visible Gaussian, as a function of the 10 raw inputs
// (mean, quaternion, log-scales).
Eigen::VectorXd projection_outputs(const Camera<double>& cam, const Eigen::VectorXd& x) {
  ProjectedGaussian<double> pg;
  const Cull c = project_gaussian<double>(cam, x.segment<3>(0), x.segment<4>(3), x.segment<3>(7),
                                          0.3, 3.0, &pg);
  REQUIRE(c == Cull::none);
  Eigen::VectorXd y(6);
  y << pg.mean2d, pg.conic, pg.depth;
  return y;
}

void check_projection_vjp(const Camera<double>& cam, const Eigen::VectorXd& x, test::Rng& rng) {
  const Eigen::MatrixXd J = test::central_jacobian(
      [&](const Eigen::VectorXd& v) { return projection_outputs(cam, v); }, x, 1e-6);
  // Every output direction separately: v = e_k gives row k of J.
  for (int k = 0; k < 6; ++k) {
    CAPTURE(k);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(6);
    v(k) = 1;
    v += 0.1 * Eigen::VectorXd::NullaryExpr(6, [&] { return rng.uniform(); });
    ProjectedGaussian<double> pg;
    project_gaussian<double>(cam, x.segment<3>(0), x.segment<4>(3), x.segment<3>(7), 0.3, 3.0, &pg);
    Vector3<double> v_mean, v_ls, v_tan;
    Vector4<double> v_q;
    project_gaussian_vjp<double>(cam, x.segment<3>(0), x.segment<4>(3), x.segment<3>(7), 0.3,
                                 pg.conic, v.segment<2>(0), v.segment<3>(2), v(5), &v_mean, &v_q,
                                 &v_tan, &v_ls);
    Eigen::VectorXd analytic(10);
    analytic << v_mean, v_q, v_ls;
    const Eigen::VectorXd numeric = J.transpose() * v;
    CHECK(test::relative_error(analytic, numeric) < 1e-7);
    // Right tangent: d/dφ of the outputs at q̂ ⊗ Exp(φ).
    const Quaternion<double> qh = from_wxyz(Vector4<double>(x.segment<4>(3))).normalized();
    const Eigen::MatrixXd Jt = test::central_jacobian_perturbed(
        [&](const Eigen::VectorXd& phi) {
          Eigen::VectorXd xp = x;
          xp.segment<4>(3) = to_wxyz(Quaternion<double>(qh * so3::exp(Vector3<double>(phi))));
          return projection_outputs(cam, xp);
        },
        3, 1e-6);
    CHECK(test::relative_error(v_tan, Eigen::VectorXd(Jt.transpose() * v)) < 1e-7);
  }
}

}  // namespace

TEST_CASE("project_gaussian_vjp matches central differences") {
  for (std::uint64_t seed = 800; seed < 806; ++seed) {
    test::Rng rng(seed);
    CAPTURE(seed);
    const auto cam = test::test_camera<double>(64, 48, 50.0, rng.quaternion(), rng.vec3());
    Eigen::VectorXd x(10);
    x.segment<3>(0) = test::world_at_pixel(cam, rng.uniform(5, 59), rng.uniform(5, 43), rng.uniform(1, 6));
    x.segment<4>(3) = to_wxyz(rng.quaternion()) * rng.uniform(0.5, 2);
    x.segment<3>(7) = Vector3<double>(rng.uniform(-3, -1), rng.uniform(-3, -1), rng.uniform(-3, -1));
    check_projection_vjp(cam, x, rng);
  }
}

TEST_CASE("project_gaussian_vjp with gsplat's field-of-view clamp active") {
  // A wide Gaussian whose centre lies beyond 1.3x the half field of view (x/z clamped), so J
  // uses the clamped tx; the radius still reaches the image.
  test::Rng rng(810);
  const auto cam = test::test_camera<double>(64, 48, 50.0);
  for (double u : {-60.0, 130.0}) {
    CAPTURE(u);
    Eigen::VectorXd x(10);
    x.segment<3>(0) = test::world_at_pixel(cam, u, 20.0, 3.0);
    x.segment<4>(3) = to_wxyz(rng.quaternion());
    x.segment<3>(7) = Vector3<double>(std::log(2.0), std::log(1.2), std::log(0.7));
    splat::detail::ProjectionState<double> st;
    splat::detail::projection_state<double>(cam, x.segment<3>(0), x.segment<4>(3), x.segment<3>(7), 0.3, &st);
    CHECK_FALSE(st.u_free);
    CHECK(st.v_free);
    check_projection_vjp(cam, x, rng);
  }
}

TEST_CASE("rotation matrix vjp matches central differences") {
  test::Rng rng(820);
  for (int it = 0; it < 5; ++it) {
    const Vector4<double> q = to_wxyz(rng.quaternion()) * rng.uniform(0.5, 2);
    Matrix3<double> V;
    for (int k = 0; k < 9; ++k) V(k) = rng.uniform();
    const Eigen::MatrixXd J = test::central_jacobian(
        [&](const Eigen::VectorXd& v) {
          const Matrix3<double> R = rotmat_from_unit_wxyz<double>(v);
          return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(R.data(), 9));
        },
        q);
    const Eigen::VectorXd numeric = J.transpose() * Eigen::Map<const Eigen::VectorXd>(V.data(), 9);
    CHECK(test::relative_error(rotmat_from_unit_wxyz_vjp<double>(q, V), numeric) < 1e-8);
    // On the unit sphere the polynomial is the rotation matrix.
    const Vector4<double> qn = q.normalized();
    CHECK((rotmat_from_unit_wxyz<double>(qn) - from_wxyz(qn).toRotationMatrix()).norm() < 1e-14);
  }
}

TEST_CASE("SH basis: derivatives, orthonormality on the sphere, colour vjp") {
  test::Rng rng(830);
  // Orthonormality: ∫ Y_a Y_b dΩ = δ_ab, by quasi-Monte-Carlo over a Fibonacci sphere.
  const int n = 20000;
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(16, 16);
  for (int i = 0; i < n; ++i) {
    const double z = 1 - (2.0 * i + 1) / n, r = std::sqrt(1 - z * z), phi = i * 2.399963229728653;
    double Y[16];
    sh_basis<double>(3, Vector3<double>(r * std::cos(phi), r * std::sin(phi), z), Y);
    for (int a = 0; a < 16; ++a)
      for (int b = 0; b < 16; ++b) gram(a, b) += Y[a] * Y[b] * 4 * M_PI / n;
  }
  CHECK((gram - Eigen::MatrixXd::Identity(16, 16)).cwiseAbs().maxCoeff() < 1e-3);

  for (int it = 0; it < 4; ++it) {
    const Vector3<double> d = rng.vec3();
    double Y[16], dY[48];
    sh_basis<double>(3, d, Y, dY);
    const Eigen::MatrixXd J = test::central_jacobian(
        [&](const Eigen::VectorXd& v) {
          Eigen::VectorXd y(16);
          sh_basis<double>(3, Vector3<double>(v), y.data());
          return y;
        },
        d);
    for (int b = 0; b < 16; ++b) {
      CAPTURE(b);
      CHECK(test::relative_error(Vector3<double>(dY[3 * b], dY[3 * b + 1], dY[3 * b + 2]),
                                 Eigen::VectorXd(J.row(b).transpose()), 1e-6) < 1e-8);
    }
  }

  for (int degree = 0; degree <= 3; ++degree) {
    CAPTURE(degree);
    const int K = sh_basis_count(degree), C = 3;
    Eigen::VectorXd coeffs(K * C);
    for (int k = 0; k < K * C; ++k) coeffs(k) = k < C ? (k == 1 ? -3.0 : 0.8) : 0.3 * rng.uniform();
    const Vector3<double> dir = 3 * rng.vec3();
    const Vector3<double> vcol(0.7, -0.4, 1.1);
    Eigen::VectorXd x(3 + K * C);
    x << dir, coeffs;
    auto f = [&](const Eigen::VectorXd& v) {
      Eigen::VectorXd c(C);
      sh_to_color<double>(degree, C, Vector3<double>(v.head<3>()), v.data() + 3, c.data());
      return c;
    };
    Eigen::VectorXd col = f(x);
    CHECK(col(1) == 0.0);  // channel 1 is clamped at 0
    const Eigen::MatrixXd J = test::central_jacobian(f, x);
    Eigen::VectorXd vco(K * C);
    const Vector3<double> vdir = sh_to_color_vjp<double>(degree, C, dir, coeffs.data(), vcol.data(), vco.data());
    Eigen::VectorXd analytic(3 + K * C);
    analytic << vdir, vco;
    CHECK(test::relative_error(analytic, Eigen::VectorXd(J.transpose() * vcol)) < 1e-8);
  }
}

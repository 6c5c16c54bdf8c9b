// Small pieces of the pipeline: the variant ladder, the stage-2 photometric loss and its
// gradient, Adam (vector and right-tangent rotation steps), and pruning.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"
#include "trainer/adam.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/stage2.hpp"
#include "trainer/variant.hpp"

using trainer::Rigidity;
using trainer::Variant;
using trainer::VariantSpec;

TEST_CASE("parse_variant: the six rungs of the ladder and their specs") {
  struct Expected {
    const char* name;
    Variant variant;
    bool semantic;
    Rigidity rigidity;
    bool lrm;
  } expected[] = {
      {"base", Variant::base, false, Rigidity::none, false},
      {"mosca", Variant::mosca, false, Rigidity::arap, false},
      {"smg-only", Variant::smg_only, true, Rigidity::arap, false},
      {"no-carap", Variant::no_carap, true, Rigidity::arap, true},
      {"no-lrm", Variant::no_lrm, true, Rigidity::carap, false},
      {"full", Variant::full, true, Rigidity::carap, true},
  };
  CHECK(trainer::variant_names().size() == 6u);
  for (const Expected& e : expected) {
    const std::string name = e.name;
    CAPTURE(name);
    VariantSpec s;
    s.semantic_graph = !e.semantic;  // make sure every field is written
    s.lrm = !e.lrm;
    REQUIRE(trainer::parse_variant(e.name, &s));
    CHECK(s.variant == e.variant);
    CHECK(s.semantic_graph == e.semantic);
    CHECK(s.rigidity == e.rigidity);
    CHECK(s.lrm == e.lrm);
    CHECK(trainer::to_string(e.variant) == e.name);
    const VariantSpec v = trainer::variant_spec(e.variant);
    CHECK(v.variant == s.variant);
    CHECK(v.semantic_graph == s.semantic_graph);
    CHECK(v.rigidity == s.rigidity);
    CHECK(v.lrm == s.lrm);
  }
  for (const char* bad : {"Full", "", "full ", "no_lrm", "smg"}) {
    const std::string bad_name = bad;
    CAPTURE(bad_name);
    VariantSpec s;
    s.variant = Variant::mosca;
    CHECK_FALSE(trainer::parse_variant(bad, &s));
    CHECK(s.variant == Variant::mosca);  // untouched on failure
  }
}

TEST_CASE("photometric_loss<double>: values and gradient against finite differences") {
  SMG_TEST_RNG(rng, 7401);
  const int W = 7, H = 5, n = W * H;
  const double lambda = 0.37;
  std::vector<double> image(3 * n), depth(n);
  std::vector<float> rgb(3 * n), target_depth(n);
  // Targets differ from the renders by at least 0.05 (L1's kink is far from every FD step).
  const auto offset = [&] { return (rng.uniform() < 0 ? -1.0 : 1.0) * rng.uniform(0.05, 0.3); };
  for (int k = 0; k < 3 * n; ++k) {
    image[k] = rng.uniform(0.2, 0.8);
    rgb[k] = static_cast<float>(image[k] + offset());
  }
  int valid = 0;
  for (int k = 0; k < n; ++k) {
    depth[k] = rng.uniform(1.0, 3.0);
    const bool prior = k % 4 != 1;  // every fourth pixel has no depth prior
    target_depth[k] = prior ? static_cast<float>(depth[k] + offset()) : 0.0f;
    valid += prior ? 1 : 0;
  }
  std::vector<double> gi(3 * n, -7.0), gd(n, -7.0);
  double l1 = 0, dl1 = 0;
  trainer::photometric_loss<double>(image.data(), depth.data(), rgb.data(), target_depth.data(), W, H, lambda,
                                    gi.data(), gd.data(), &l1, &dl1);
  // Values: the means as documented.
  double s = 0, sd = 0;
  for (int k = 0; k < 3 * n; ++k) s += std::abs(image[k] - static_cast<double>(rgb[k]));
  for (int k = 0; k < n; ++k)
    if (target_depth[k] > 0) sd += std::abs(depth[k] - static_cast<double>(target_depth[k]));
  CHECK(l1 == doctest::Approx(s / (3.0 * n)).epsilon(1e-14));
  CHECK(dl1 == doctest::Approx(sd / valid).epsilon(1e-14));

  const auto total = [&] {
    std::vector<double> a(3 * n), b(n);
    double x = 0, y = 0;
    trainer::photometric_loss<double>(image.data(), depth.data(), rgb.data(), target_depth.data(), W, H, lambda,
                                      a.data(), b.data(), &x, &y);
    return x + lambda * y;
  };
  double err = 0, ref = 0;
  for (int k = 0; k < 3 * n; ++k) {
    const double fd = smg::test::central_difference(image[k], total);
    err = std::max(err, std::abs(fd - gi[k]));
    ref = std::max(ref, std::abs(fd));
  }
  int zero_where_no_prior = 0;
  for (int k = 0; k < n; ++k) {
    const double fd = smg::test::central_difference(depth[k], total);
    err = std::max(err, std::abs(fd - gd[k]));
    ref = std::max(ref, std::abs(fd));
    if (!(target_depth[k] > 0) && gd[k] == 0.0 && fd == 0.0) ++zero_where_no_prior;
  }
  CAPTURE(err);
  CHECK(ref > 1e-3);
  CHECK(err < 1e-7 * ref);
  CHECK(zero_where_no_prior == n - valid);

  // No depth prior anywhere: depth term 0, its gradient 0 (and no division by zero).
  std::vector<float> none(n, 0.0f);
  trainer::photometric_loss<double>(image.data(), depth.data(), rgb.data(), none.data(), W, H, lambda, gi.data(),
                                    gd.data(), &l1, &dl1);
  CHECK(dl1 == 0.0);
  for (double g : gd) CHECK(g == 0.0);
  // float and double agree.
  std::vector<float> fi(image.begin(), image.end()), fdp(depth.begin(), depth.end()), fgi(3 * n), fgd(n);
  double fl1 = 0, fdl1 = 0;
  trainer::photometric_loss<double>(image.data(), depth.data(), rgb.data(), target_depth.data(), W, H, lambda,
                                    gi.data(), gd.data(), &l1, &dl1);
  trainer::photometric_loss<float>(fi.data(), fdp.data(), rgb.data(), target_depth.data(), W, H, lambda, fgi.data(),
                                   fgd.data(), &fl1, &fdl1);
  CHECK(fl1 == doctest::Approx(l1).epsilon(1e-6));
  CHECK(fdl1 == doctest::Approx(dl1).epsilon(1e-6));
  for (int k = 0; k < 3 * n; ++k) CHECK(fgi[k] == doctest::Approx(gi[k]).epsilon(1e-6));
}

TEST_CASE("Adam::step: first step is lr against the gradient's sign; a quadratic decreases") {
  SMG_TEST_RNG(rng, 7501);
  const int n = 6;
  std::vector<double> x(n), a(n), c(n), g(n);
  for (int k = 0; k < n; ++k) {
    x[k] = rng.uniform(-2, 2);
    a[k] = rng.uniform(0.5, 3.0);
    c[k] = rng.uniform(-1, 1);
  }
  const auto f = [&] {
    double s = 0;
    for (int k = 0; k < n; ++k) s += a[k] * (x[k] - c[k]) * (x[k] - c[k]);
    return s;
  };
  const auto grad = [&] {
    for (int k = 0; k < n; ++k) g[k] = 2 * a[k] * (x[k] - c[k]);
  };
  const double lr = 0.05, f0 = f();
  trainer::Adam<double> adam(n, lr);
  const std::vector<double> x0 = x;
  grad();
  adam.step(x.data(), g.data());
  CHECK(adam.steps() == 1);
  for (int k = 0; k < n; ++k) CHECK(x[k] - x0[k] == doctest::Approx(g[k] > 0 ? -lr : lr).epsilon(1e-9));
  for (int it = 0; it < 400; ++it) {
    grad();
    adam.step(x.data(), g.data());
  }
  CAPTURE(f0);
  CAPTURE(f());
  CHECK(f() < 1e-3 * f0);
  // compact keeps the moments of the kept rows only.
  adam.compact({1, 0, 1}, 2);
  CHECK(adam.size() == 4u);
}

TEST_CASE("Adam::step_rotations: unit quaternions, steps against the right-tangent gradient") {
  SMG_TEST_RNG(rng, 7502);
  // L = Σ_r |Log(target_r^-1 q_r)|^2; its right-tangent gradient is 2 Log(target_r^-1 q_r).
  const int n = 3;
  std::vector<Eigen::Quaterniond> target(n);
  std::vector<double> q(4 * n), g(3 * n);
  for (int r = 0; r < n; ++r) {
    target[r] = rng.quaternion();
    smg::to_wxyz(Eigen::Quaterniond(target[r] * rng.rotation_with_angle(0.8 + 0.5 * r)), q.data() + 4 * r);
  }
  const auto angle = [&](int r) { return smg::so3::log(Eigen::Quaterniond(target[r].conjugate() * smg::from_wxyz(q.data() + 4 * r))).norm(); };
  const auto loss = [&] {
    double s = 0;
    for (int r = 0; r < n; ++r) s += angle(r) * angle(r);
    return s;
  };
  const auto grad = [&] {
    for (int r = 0; r < n; ++r) {
      const Eigen::Vector3d phi = smg::so3::log(Eigen::Quaterniond(target[r].conjugate() * smg::from_wxyz(q.data() + 4 * r)));
      for (int c = 0; c < 3; ++c) g[3 * r + c] = 2 * phi(c);
    }
  };
  const double lr = 0.05, L0 = loss();
  trainer::Adam<double> adam(3 * n, lr);
  // The first step moves each rotation by the tangent (-lr, -lr, -lr) ⊙ sign(g): check exactly.
  grad();
  const std::vector<double> q0 = q, g0 = g;
  adam.step_rotations(q.data(), g.data());
  for (int r = 0; r < n; ++r) {
    const Eigen::Vector3d step = smg::so3::log(Eigen::Quaterniond(smg::from_wxyz(q0.data() + 4 * r).conjugate() * smg::from_wxyz(q.data() + 4 * r)));
    for (int c = 0; c < 3; ++c) CHECK(step(c) == doctest::Approx(g0[3 * r + c] > 0 ? -lr : lr).epsilon(1e-9));
  }
  CHECK(loss() < L0);
  double worst_norm = 0;
  for (int it = 0; it < 300; ++it) {
    grad();
    adam.step_rotations(q.data(), g.data());
    for (int r = 0; r < n; ++r) worst_norm = std::max(worst_norm, std::abs(Eigen::Map<const Eigen::Vector4d>(q.data() + 4 * r).norm() - 1.0));
  }
  CAPTURE(L0);
  CAPTURE(loss());
  CHECK(worst_norm < 1e-14);
  CHECK(loss() < 1e-3 * L0);
}

TEST_CASE("Adam: steps run in parallel chunks, bit-identical for any thread count and grain") {
  // The steps are per value (per row for rotations), so splitting them differently must not
  // change a bit (stage 2 relies on it: its metrics do not depend on --threads).
  SMG_TEST_RNG(rng, 7503);
  const int n = 1001;  // rows: not a multiple of any grain used below
  std::vector<float> x0(3 * n), g(3 * n);
  std::vector<double> q0(4 * n), gq(3 * n);
  for (auto& v : x0) v = static_cast<float>(rng.uniform(-1, 1));
  for (auto& v : g) v = static_cast<float>(rng.uniform(-1, 1));
  for (int r = 0; r < n; ++r) smg::to_wxyz(rng.quaternion(), q0.data() + 4 * r);
  for (auto& v : gq) v = rng.uniform(-1, 1);
  const auto run = [&](smg::ParallelOptions par, std::vector<float>& x, std::vector<double>& q) {
    x = x0;
    q = q0;
    trainer::Adam<float> a(x.size(), 1e-2);
    trainer::Adam<double> b(gq.size(), 1e-2);
    for (int it = 0; it < 5; ++it) {
      a.step(x.data(), g.data(), par);
      b.step_rotations(q.data(), gq.data(), par);
    }
  };
  std::vector<float> x1, x2;
  std::vector<double> q1, q2;
  run({1, 0}, x1, q1);
  for (const smg::ParallelOptions par : {smg::ParallelOptions{2, 0}, smg::ParallelOptions{3, 7},
                                         smg::ParallelOptions{2, 1}}) {
    CAPTURE(par.threads);
    CAPTURE(par.grain);
    run(par, x2, q2);
    CHECK(x1 == x2);
    CHECK(q1 == q2);
  }
}

TEST_CASE("prune: removes faint and huge Gaussians, compacts the table and the skinning rows") {
  // 4 static rows, 5 dynamic rows; every row tagged by its colour so moves can be followed.
  trainer::GaussianModel<double> m;
  const int F = 4, P = 5, G = F + P, D = 2;
  m.fixed = F;
  m.table.resize(G);
  m.skin.width = D;
  m.skin.drivers.resize(P * D);
  m.skin.weights.resize(P * D);
  m.skin.t_ref.resize(P);
  m.skin.sigma.assign(3, 0.05);
  const double min_opacity = 0.01, max_scale = 0.15;
  const double logit_ok = std::log(0.5), logit_faint = std::log(0.005 / 0.995);
  const double scale_ok = std::log(0.05), scale_huge = std::log(0.3);
  for (int r = 0; r < G; ++r) {
    for (int c = 0; c < 3; ++c) {
      m.table.means[3 * r + c] = 10.0 * r + c;
      m.table.log_scales[3 * r + c] = scale_ok;
      m.table.colors[3 * r + c] = r;
    }
    for (int c = 0; c < 4; ++c) m.table.quats[4 * r + c] = 100.0 * r + c;
    m.table.opacity[r] = logit_ok;
  }
  for (int p = 0; p < P; ++p) {
    m.skin.drivers[p * D] = p % 3;
    m.skin.drivers[p * D + 1] = (p + 1) % 3;
    m.skin.weights[p * D] = 1.0 + p;
    m.skin.weights[p * D + 1] = 0.5 + p;
    m.skin.t_ref[p] = p;
  }
  m.table.opacity[1] = logit_faint;           // static, faint
  m.table.log_scales[3 * 3 + 2] = scale_huge; // static, huge along z only
  m.table.log_scales[3 * 5 + 0] = scale_huge; // dynamic 1
  m.table.opacity[7] = logit_faint;           // dynamic 3
  std::vector<std::uint8_t> expect(G);
  for (int r = 0; r < G; ++r) {
    const double o = 1.0 / (1.0 + std::exp(-m.table.opacity[r]));
    const double s = std::exp(std::max({m.table.log_scales[3 * r], m.table.log_scales[3 * r + 1], m.table.log_scales[3 * r + 2]}));
    expect[r] = (o >= min_opacity && s <= max_scale) ? 1 : 0;
  }
  const trainer::GaussianModel<double> before = m;
  std::vector<std::uint8_t> keep;
  const int removed = trainer::prune(m, min_opacity, max_scale, &keep);
  CHECK(keep == expect);
  int expected_removed = 0, expected_fixed = 0;
  for (int r = 0; r < G; ++r) {
    expected_removed += expect[r] ? 0 : 1;
    expected_fixed += (r < F && expect[r]) ? 1 : 0;
  }
  REQUIRE(expected_removed == 4);
  CHECK(removed == expected_removed);
  CHECK(m.count() == G - expected_removed);
  CHECK(m.fixed == expected_fixed);
  CHECK(m.dynamic() == m.count() - m.fixed);
  CHECK(m.skin.drivers.size() == static_cast<std::size_t>(m.dynamic() * D));
  CHECK(m.skin.weights.size() == static_cast<std::size_t>(m.dynamic() * D));
  CHECK(m.skin.t_ref.size() == static_cast<std::size_t>(m.dynamic()));
  CHECK(m.skin.sigma == before.skin.sigma);  // per node, untouched
  // Every surviving row is the original row, with its skinning row when dynamic.
  int w = 0;
  for (int r = 0; r < G; ++r) {
    if (!expect[r]) continue;
    CAPTURE(r);
    for (int c = 0; c < 3; ++c) {
      CHECK(m.table.means[3 * w + c] == before.table.means[3 * r + c]);
      CHECK(m.table.log_scales[3 * w + c] == before.table.log_scales[3 * r + c]);
      CHECK(m.table.colors[3 * w + c] == before.table.colors[3 * r + c]);
    }
    for (int c = 0; c < 4; ++c) CHECK(m.table.quats[4 * w + c] == before.table.quats[4 * r + c]);
    CHECK(m.table.opacity[w] == before.table.opacity[r]);
    CHECK((w < m.fixed) == (r < F));
    if (r >= F) {
      const int p = r - F, q = w - m.fixed;
      for (int k = 0; k < D; ++k) {
        CHECK(m.skin.drivers[q * D + k] == before.skin.drivers[p * D + k]);
        CHECK(m.skin.weights[q * D + k] == before.skin.weights[p * D + k]);
      }
      CHECK(m.skin.t_ref[q] == before.skin.t_ref[p]);
    }
    ++w;
  }
  // Nothing left to prune: a no-op with an all-ones mask.
  const trainer::GaussianModel<double> after = m;
  CHECK(trainer::prune(m, min_opacity, max_scale, &keep) == 0);
  CHECK(keep == std::vector<std::uint8_t>(static_cast<std::size_t>(after.count()), 1));
  CHECK(m.table.means == after.table.means);
  CHECK(m.fixed == after.fixed);
  CHECK(m.skin.drivers == after.skin.drivers);
}

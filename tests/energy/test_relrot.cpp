// Term-specific tests of relative-rotation consistency (E25, smg/energy/relrot.hpp,
// docs/math/terms/relrot.md). The operator list (tests/support/operators.hpp) gives the generic
// ones (central differences, AutoDiffScalar, float against double, threads, hard cases, the fused
// step, the CUDA host scheme); here: the energy against one written out with Eigen's quaternion
// products for every penalty and normalisation, invariance to a common rotation on either side,
// the raw sign of q, zero weights, padding and the validation message.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "smg/core/quaternion.hpp"
#include "smg/energy.hpp"
#include "support/random.hpp"

namespace {

struct RelrotScene {
  smg::Index T, N, K;
  std::vector<double> q;           // [T][N][4], raw (norms 0.5 .. 2)
  std::vector<std::int32_t> idx;   // [N][K], −1 padding
  std::vector<double> w;           // [N][K]
  smg::QuaternionsView<const double> view() const { return {q.data(), T, N}; }
  smg::NeighborsView<double, std::int32_t> graph() const { return {idx.data(), w.data(), N, K}; }
};

RelrotScene relrot_scene(smg::Index T, smg::Index N, smg::Index K, unsigned seed) {
  SMG_TEST_RNG(rng, seed);
  RelrotScene s{T, N, K, std::vector<double>(static_cast<std::size_t>(4 * T * N)),
                std::vector<std::int32_t>(static_cast<std::size_t>(N * K), -1),
                std::vector<double>(static_cast<std::size_t>(N * K), 0.0)};
  for (smg::Index i = 0; i < N; ++i) {
    smg::Quaternion<double> r = rng.quaternion();
    for (smg::Index t = 0; t < T; ++t) {
      r = r * smg::Quaternion<double>(1.0, 0.2 * rng.uniform(), 0.2 * rng.uniform(), 0.2 * rng.uniform()).normalized();
      const Eigen::Vector4d v = smg::to_wxyz(r) * rng.uniform(0.5, 2.0);
      for (int c = 0; c < 4; ++c) s.q[static_cast<std::size_t>(4 * (t * N + i) + c)] = v(c);
    }
    const smg::Index deg = 1 + (i % K);  // rows of 1 .. K neighbours, the rest −1
    for (smg::Index k = 0; k < deg; ++k) {
      s.idx[static_cast<std::size_t>(i * K + k)] = static_cast<std::int32_t>((i + 1 + k * 3) % N);
      s.w[static_cast<std::size_t>(i * K + k)] = k == 1 ? 0.0 : rng.uniform(0.1, 1.0);  // one zero weight
    }
  }
  return s;
}

// (E25) written out: Eigen's products and normalisations, each term's penalty in full.
double relrot_reference(const RelrotScene& s, const smg::RelrotOptions& o) {
  auto rel = [&](smg::Index t, smg::Index i) {
    const smg::Quaternion<double> a = smg::from_wxyz(&s.q[static_cast<std::size_t>(4 * ((t + 1) * s.N + i))]).normalized();
    const smg::Quaternion<double> b = smg::from_wxyz(&s.q[static_cast<std::size_t>(4 * (t * s.N + i))]).normalized();
    return smg::to_wxyz(smg::Quaternion<double>(a * b.conjugate()));
  };
  double sum = 0;
  smg::Index edges = 0;
  for (smg::Index i = 0; i < s.N; ++i)
    for (smg::Index k = 0; k < s.K; ++k) {
      const std::int32_t j = s.idx[static_cast<std::size_t>(i * s.K + k)];
      if (j < 0) break;
      ++edges;
      const double w = s.w[static_cast<std::size_t>(i * s.K + k)];
      for (smg::Index t = 0; t + 1 < s.T; ++t) {
        const double n2 = (rel(t, j) - rel(t, i)).squaredNorm();
        if (o.penalty == smg::Penalty::sqrt_weighted) sum += std::sqrt(w * n2 + o.penalty_eps);
        else if (o.penalty == smg::Penalty::norm) sum += w * std::sqrt(n2);
        else sum += w * n2;
      }
    }
  const double k = o.normalization == smg::Normalization::mean ? o.weight / double((s.T - 1) * edges) : o.weight;
  return k * sum;
}

}  // namespace

TEST_CASE("relrot: the energy equals (E25) written out, every penalty and normalisation") {
  const RelrotScene s = relrot_scene(6, 9, 4, 5101);
  for (smg::Penalty p : smg::kPenalties)
    for (smg::Normalization n : {smg::Normalization::sum, smg::Normalization::mean}) {
      const std::string penalty = smg::to_string(p);
    CAPTURE(penalty);
      CAPTURE(int(n));
      smg::RelrotOptions o;
      o.penalty = p;
      o.normalization = n;
      o.weight = 1.7;
      o.penalty_eps = 1e-6;  // large enough to show in the sum
      const double ref = relrot_reference(s, o);
      CHECK(ref > 0.0);
      CHECK(double(smg::relrot<double>(s.view(), s.graph(), o)) == doctest::Approx(ref).epsilon(1e-13));
      // The fused step with this term alone gives the same.
      smg::RegularizerOptions ro;
      smg::for_each_term(ro, [](const char*, bool& on, const auto&) { on = false; });
      ro.terms.relrot = true;
      ro.relrot = o;
      const std::vector<double> x(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
      const auto r = smg::regularizers<double>(smg::PositionsView<const double>(x.data(), s.T, s.N), s.view(), {},
                                               s.graph(), ro);
      CHECK(double(r.relrot) == doctest::Approx(ref).epsilon(1e-13));
    }
}

TEST_CASE("relrot: invariant to a common rotation of every node, on either side; q's sign is raw") {
  const RelrotScene s = relrot_scene(5, 8, 3, 5102);
  smg::RelrotOptions o;
  o.penalty = smg::Penalty::squared;
  const double e0 = smg::relrot<double>(s.view(), s.graph(), o);
  SMG_TEST_RNG(rng, 5103);
  const smg::Quaternion<double> g = rng.quaternion();
  for (const bool left : {true, false}) {
    CAPTURE(left);
    RelrotScene m = s;
    for (smg::Index k = 0; k < s.T * s.N; ++k) {
      const smg::Quaternion<double> q = smg::from_wxyz(&s.q[static_cast<std::size_t>(4 * k)]);
      const Eigen::Vector4d v = smg::to_wxyz(smg::Quaternion<double>(left ? g * q : q * g));
      for (int c = 0; c < 4; ++c) m.q[static_cast<std::size_t>(4 * k + c)] = v(c);
    }
    CHECK(double(smg::relrot<double>(m.view(), m.graph(), o)) == doctest::Approx(e0).epsilon(1e-12));
  }
  // −q at one (frame, node) flips r on its two pairs: not the same energy (no canonicalisation),
  // and still what (E25) written out gives.
  RelrotScene f = s;
  for (int c = 0; c < 4; ++c) f.q[static_cast<std::size_t>(4 * (2 * s.N + 3) + c)] *= -1.0;
  const double ef = smg::relrot<double>(f.view(), f.graph(), o);
  CHECK(std::abs(ef - e0) > 1e-3 * e0);
  CHECK(ef == doctest::Approx(relrot_reference(f, o)).epsilon(1e-13));
}

TEST_CASE("relrot: zero weights and still rotations") {
  RelrotScene s = relrot_scene(4, 6, 3, 5104);
  // Every rotation constant in time: r = 1 everywhere, d = 0; sqrt_weighted leaves k sqrt(ε) per
  // term (zero-weight edges included), the others 0; the gradient is exactly 0.
  for (smg::Index t = 1; t < s.T; ++t)
    for (smg::Index k = 0; k < 4 * s.N; ++k) s.q[static_cast<std::size_t>(4 * t * s.N + k)] = s.q[static_cast<std::size_t>(k)];
  const smg::Index terms = (s.T - 1) * smg::edge_count(s.graph());
  for (smg::Penalty p : smg::kPenalties) {
    const std::string penalty = smg::to_string(p);
    CAPTURE(penalty);
    smg::RelrotOptions o;
    o.penalty = p;
    std::vector<double> g(static_cast<std::size_t>(3 * s.T * s.N), 0.0);
    const double e = smg::relrot<double>(s.view(), s.graph(), o, smg::TangentsView<double>(g.data(), s.T, s.N));
    if (p == smg::Penalty::sqrt_weighted)
      CHECK(e == doctest::Approx(double(terms) * std::sqrt(1e-20)).epsilon(1e-12));
    else
      CHECK(std::abs(e) < 1e-13);  // r's rounding: |d| ~ 1e-16 per term (norm), its square
    for (double v : g) CHECK(std::abs(v) < 1e-12);
  }
  // All weights zero: squared and norm give exactly 0.
  std::fill(s.w.begin(), s.w.end(), 0.0);
  const RelrotScene moving = relrot_scene(4, 6, 3, 5105);
  s.q = moving.q;
  for (smg::Penalty p : {smg::Penalty::squared, smg::Penalty::norm}) {
    smg::RelrotOptions o;
    o.penalty = p;
    CHECK(double(smg::relrot<double>(s.view(), s.graph(), o)) == 0.0);
  }
}

TEST_CASE("relrot: validation names the argument") {
  const RelrotScene s = relrot_scene(4, 5, 2, 5106);
  smg::RelrotOptions o;
  o.penalty_eps = 0.0;
  smg::Status st = smg::validate_relrot<double>(s.view(), s.graph(), o);
  REQUIRE_FALSE(st);
  CHECK(st.message().find("penalty_eps") != std::string::npos);
  o = smg::RelrotOptions{};
  o.weight = -1.0;
  st = smg::validate_relrot<double>(s.view(), s.graph(), o);
  REQUIRE_FALSE(st);
  CHECK(st.message().find("RelrotOptions") != std::string::npos);
  CHECK(smg::validate_relrot<double>(s.view(), s.graph(), smg::RelrotOptions{}));
}

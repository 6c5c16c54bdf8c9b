// The fused regulariser step on the GPU (smg/cuda/regularizers.cuh) against the CPU
// smg::regularizers().
//
// Suite "cuda-host" (runs without a GPU): the CUDA driver (cuda/driver.cuh) through its
// HostBackend, which runs the kernels' per-element steps (confidence_inputs_at, confidence_at,
// fused_rigid_node_at, AccelElement, lrm_term_at, lrm_gather_at, lrm_velocity_chunk_at) in host
// loops in the launcher's phase order, with chunks of 1, 2, 3 frames and the whole sequence, for every subset of the terms, float and double, int32
// and int64 indices, tangent and raw rotation gradients, mean normalisation and hard cases; the
// plan's memory bound; the host-side argument checks. Double agrees to 1e-11 relative to the
// largest value (sums associated differently: the rigid gradient of a node is summed over its
// out-edges then in-edges, the CPU's per block and frame), float to 1e-5; the confidences are
// bit-identical (same element functions in the same order).
// Default suite (needs a GPU): the launcher itself against the CPU, and repeat runs bitwise.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "cuda/cuda_test_support.cuh"
#include "energy/fused_options.hpp"
#include "energy/scene.hpp"
#include "smg/cuda/regularizers.cuh"
#include "smg/energy/regularizers.hpp"

namespace fused_cuda_test {

using smg::Index;

// A scene in scalar S with indices I (the shared test scene is double / int32).
template <class S, class I>
struct Case {
  Index T, N, K;
  std::vector<S> x, q, w;
  std::vector<std::uint8_t> v;
  std::vector<I> idx;
  explicit Case(const smg::test::Scene<double>& s)
      : T(s.T), N(s.N), K(s.K), x(s.x.begin(), s.x.end()), q(s.q.begin(), s.q.end()),
        w(s.w.begin(), s.w.end()), v(s.v), idx(s.idx.begin(), s.idx.end()) {}
  smg::PositionsView<const S> positions() const { return {x.data(), T, N}; }
  smg::QuaternionsView<const S> rotations() const { return {q.data(), T, N}; }
  smg::VisibilityView<const std::uint8_t> visibility() const { return {v.data(), T, N}; }
  smg::NeighborsView<S, I> graph() const { return {idx.data(), w.data(), N, K}; }
};

template <class S>
struct Out {
  smg::RegularizerResult<S> e;
  std::vector<S> conf, gx, gr;
};

struct Flags {
  bool raw = false, grad_x = true, grad_r = true, vis = true, conf_out = true;
};

template <class S>
smg::RotationGradientView<S> rotation_view(std::vector<S>& g, Index T, Index N, const Flags& f) {
  if (!f.grad_r) return {};
  return f.raw ? smg::RotationGradientView<S>(smg::QuaternionsView<S>(g.data(), T, N))
               : smg::RotationGradientView<S>(smg::TangentsView<S>(g.data(), T, N));
}

template <class S>
Out<S> outputs(Index T, Index N, const Flags& f) {
  Out<S> r;
  const std::size_t TN = static_cast<std::size_t>(T * N);
  r.conf.assign(TN, S(-1));
  r.gx.assign(TN * 3, S(0.25));  // gradients are added to what is there
  r.gr.assign(TN * (f.raw ? 4 : 3), S(-0.5));
  return r;
}

// The CPU fused step (one thread).
template <class S, class I>
Out<S> cpu(const Case<S, I>& s, const smg::RegularizerOptions& o, const Flags& f) {
  Out<S> r = outputs<S>(s.T, s.N, f);
  const bool c_out = f.conf_out && o.terms.confidence;
  smg::ParallelOptions par;
  par.threads = 1;
  r.e = smg::regularizers<S, I>(
      s.positions(), s.rotations(), f.vis ? s.visibility() : smg::VisibilityView<const std::uint8_t>(),
      s.graph(), o, c_out ? smg::FrameScalarsView<S>(r.conf.data(), s.T, s.N) : smg::FrameScalarsView<S>(),
      f.grad_x ? smg::PositionsView<S>(r.gx.data(), s.T, s.N) : smg::PositionsView<S>(),
      rotation_view(r.gr, s.T, s.N, f), nullptr, par);
  return r;
}

// The in-edges of every node, as build_reverse_graph orders them (increasing slot).
template <class I>
void host_reverse(const std::vector<I>& idx, Index N, std::vector<std::int32_t>& off,
                  std::vector<std::int64_t>& ent) {
  off.assign(static_cast<std::size_t>(N + 1), 0);
  for (const I j : idx)
    if (j >= 0) ++off[static_cast<std::size_t>(j) + 1];
  for (Index j = 0; j < N; ++j) off[static_cast<std::size_t>(j + 1)] += off[static_cast<std::size_t>(j)];
  ent.assign(static_cast<std::size_t>(off.back()), 0);
  std::vector<std::int32_t> fill(off.begin(), off.end() - 1);
  for (std::size_t e = 0; e < idx.size(); ++e)
    if (idx[e] >= 0) ent[static_cast<std::size_t>(fill[static_cast<std::size_t>(idx[e])]++)] = std::int64_t(e);
}

// The CUDA driver itself (cuda/driver.cuh: the launcher's plan, phases, chunks and per-element
// steps) through its HostBackend; chunk lengths given (0: the plan's).
template <class S, class I>
Out<S> host_scheme(const Case<S, I>& s, const smg::RegularizerOptions& o, const Flags& f,
                   Index conf_chunk, Index lrm_chunk) {
  namespace cd = smg::cuda::detail;
  Out<S> r = outputs<S>(s.T, s.N, f);
  const Index T = s.T, N = s.N, K = s.K;
  const bool c_out = f.conf_out && o.terms.confidence;
  cd::FusedPlan p = cd::fused_plan<S, I>(T, N, K, o, f.grad_x, f.grad_r, true, f.vis, c_out);
  if (conf_chunk > 0) p.conf_chunk = conf_chunk;
  if (lrm_chunk > 0) p.lrm_chunk = lrm_chunk;
  std::vector<std::int32_t> off;
  std::vector<std::int64_t> ent;
  host_reverse(s.idx, N, off, ent);
  smg::RegularizerResult<S>::each_energy([](const char*, smg::Accumulator<S>& e) { e = 1e30; },
                                         r.e);  // the driver overwrites the result
  const smg::Status st = cd::drive<S, I>(
      cd::HostBackend{}, p, o, s.positions(), s.rotations(),
      f.vis ? s.visibility() : smg::VisibilityView<const std::uint8_t>(), s.graph(), off.data(),
      ent.data(), off.data() + N, &r.e,
      c_out ? smg::FrameScalarsView<S>(r.conf.data(), T, N) : smg::FrameScalarsView<S>(),
      f.grad_x ? smg::PositionsView<S>(r.gx.data(), T, N) : smg::PositionsView<S>(),
      rotation_view(r.gr, T, N, f));
  REQUIRE_MESSAGE(st, st.message());
  return r;
}

template <class S>
double rel(const std::vector<S>& a, const std::vector<S>& b) {
  double d = 0, m = 1e-300;
  for (std::size_t k = 0; k < a.size(); ++k) {
    d = std::max(d, std::abs(double(a[k]) - double(b[k])));
    m = std::max(m, std::abs(double(b[k])));
  }
  return d / m;
}

double rel(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

template <class S>
constexpr double tol() {
  return sizeof(S) == 8 ? 1e-11 : 1e-5;
}

// conf_bitwise: the host scheme computes the confidences with the CPU's arithmetic, bit for bit;
// a GPU's differs in the last bits (its maths library's exp, nvcc's FMA contraction; which of
// them was not isolated), so there they agree to rounding only (an H200, 2026-11-28: every seed,
// mask and precision differed in bits; within tol()).
template <class S>
void check_same(const Out<S>& a, const Out<S>& b, const smg::RegularizerOptions& o,
                const Flags& f, const std::string& what, bool conf_bitwise = true) {
  INFO(what);
  smg::RegularizerResult<S>::each_energy(
      [](const char* name, const smg::Accumulator<S>& x, const smg::Accumulator<S>& y) {
        INFO(name);
        CHECK(rel(double(x), double(y)) <= tol<S>());
      },
      a.e, b.e);
  if (f.conf_out && o.terms.confidence) {
    if (conf_bitwise)
      CHECK(std::memcmp(a.conf.data(), b.conf.data(), a.conf.size() * sizeof(S)) == 0);
    else
      CHECK(rel(a.conf, b.conf) <= tol<S>());
  }
  CHECK(rel(a.gx, b.gx) <= tol<S>());
  CHECK(rel(a.gr, b.gr) <= tol<S>());
}

smg::RegularizerOptions options(unsigned mask) { return smg::test::fused_options(mask); }

// f(options, flags) for each mask of `masks`, with tangent and with raw rotation gradients.
template <class F>
void each_mask_and_form(const std::vector<unsigned>& masks, F&& f) {
  for (const unsigned mask : masks) {
    CAPTURE(mask);
    const smg::RegularizerOptions o = options(mask);
    for (const bool raw : {false, true}) {
      CAPTURE(raw);
      Flags flags;
      flags.raw = raw;
      f(o, flags);
    }
  }
}

smg::test::Scene<double> scene(Index T, Index N, Index K, std::uint64_t seed) {
  smg::test::Rng rng(seed);
  return smg::test::random_scene(T, N, K, rng);
}

template <class S, class I>
void subsets_case(std::uint64_t seed) {
  CAPTURE(seed);
  CAPTURE(sizeof(S));
  CAPTURE(sizeof(I));
  const Case<S, I> s(scene(9, 23, 6, seed));
  std::vector<unsigned> every_subset;
  for (unsigned mask = 1; mask <= smg::test::fused_all_terms(); ++mask) every_subset.push_back(mask);
  each_mask_and_form(every_subset, [&](const smg::RegularizerOptions& o, const Flags& f) {
    const Out<S> ref = cpu(s, o, f);
    for (const Index chunk : {Index(1), Index(2), Index(3), Index(0)}) {
      CAPTURE(chunk);
      check_same(host_scheme(s, o, f, chunk, chunk), ref, o, f, "subset");
    }
  });
}

}  // namespace fused_cuda_test

TEST_SUITE("cuda-host") {
  TEST_CASE("cuda regularizers: host scheme equals the CPU fused step for every subset of terms") {
    using namespace fused_cuda_test;
    subsets_case<double, std::int32_t>(11);
    subsets_case<double, std::int64_t>(12);
    subsets_case<float, std::int32_t>(13);
  }

  TEST_CASE("cuda regularizers: host scheme, outputs left out, mean normalisation, no visibility") {
    using namespace fused_cuda_test;
    const Case<double, std::int32_t> s(scene(12, 31, 8, 21));
    // Every term's normalisation mean, and its stop-gradients that are bools (detach_*) on: by
    // the options' lists, so a term added to them is run this way too.
    smg::RegularizerOptions o = options(smg::test::fused_all_terms());
    int mean = 0, detached = 0;
    smg::for_each_term(o, [&](const char*, bool, auto& term) {
      smg::for_each_option(term, [&](const char* name, auto& field) {
        using V = std::decay_t<decltype(field)>;
        if constexpr (std::is_same<V, smg::Normalization>::value) {
          field = smg::Normalization::mean;
          ++mean;
        } else if constexpr (std::is_same<V, bool>::value) {
          if (std::string(name).rfind("detach_", 0) == 0) {
            field = true;
            ++detached;
          }
        }
      });
    });
    CHECK(mean >= 4);  // at least the four terms this case had by name before the list
    CHECK(detached >= 1);
    for (int variant = 0; variant < 5; ++variant) {
      CAPTURE(variant);
      Flags f;
      f.grad_x = variant != 1;
      f.grad_r = variant != 2;
      f.vis = variant != 3;
      f.conf_out = variant != 4;
      check_same(host_scheme(s, o, f, 4, 5), cpu(s, o, f), o, f, "variant");
    }
  }

  TEST_CASE("cuda regularizers: host scheme, every option value of every term, alone, with the confidences, with all") {
    // smg::test::for_each_option_variant: each named-enum option (forms, penalties,
    // stop-gradients) at each other value, each bool flipped, of every term that is on; so an
    // option added to any term is run here with no edit.
    using namespace fused_cuda_test;
    const Case<double, std::int32_t> s(scene(8, 17, 5, 22));
    const Case<float, std::int32_t> sf(scene(8, 17, 5, 22));
    const unsigned conf = 1u << smg::test::fused_term_index("confidence");
    std::vector<unsigned> masks;
    for (unsigned k = 0; k < smg::test::fused_term_count(); ++k) {
      masks.push_back(1u << k);
      if ((1u << k) != conf) masks.push_back((1u << k) | conf);
    }
    masks.push_back(smg::test::fused_all_terms());
    int calls = 0;
    for (const unsigned mask : masks) {
      CAPTURE(mask);
      smg::RegularizerOptions base = options(mask);
      // Every term's penalty_eps at 1e-3, where its effect is visible.
      smg::for_each_term(base, [](const char*, bool, auto& term) {
        smg::for_each_option(term, [](const char* name, auto& field) {
          if constexpr (std::is_same<std::decay_t<decltype(field)>, double>::value)
            if (std::string(name) == "penalty_eps") field = 1e-3;
        });
      });
      calls += smg::test::for_each_option_variant(base, [&](const std::string& label,
                                                            const smg::RegularizerOptions& o) {
        CAPTURE(label);
        Flags f;
        check_same(host_scheme(s, o, f, 3, 2), cpu(s, o, f), o, f, "variant");
        check_same(host_scheme(sf, o, f, 2, 3), cpu(sf, o, f), o, f, "variant float");
      });
    }
    CHECK(calls >= 30);
  }

  TEST_CASE("cuda regularizers: host scheme, rotation-angle forms, weighted or not, tangent or raw") {
    using namespace fused_cuda_test;
    const Case<double, std::int32_t> s(scene(9, 13, 5, 23));
    // The angle term's bit of fused_options (its place in for_each_term): alone, with the
    // confidences, with every term.
    const unsigned angle = 1u << smg::test::fused_term_index("angle");
    const unsigned conf = 1u << smg::test::fused_term_index("confidence");
    REQUIRE(angle < (1u << smg::test::fused_term_count()));
    for (const unsigned mask : {angle, angle | conf, smg::test::fused_all_terms()})
      for (const bool velocity : {false, true})
        for (const bool weighted : {false, true})
          for (const bool raw : {false, true}) {
            CAPTURE(mask);
            CAPTURE(velocity);
            CAPTURE(weighted);
            CAPTURE(raw);
            smg::RegularizerOptions o = options(mask);
            o.angle.form = velocity ? smg::AccelForm::velocity : smg::AccelForm::acceleration;
            o.angle.confidence_weighted = weighted;
            Flags f;
            f.raw = raw;
            const Out<double> ref = cpu(s, o, f);
            CHECK(double(ref.e.angle) > 0.0);
            check_same(host_scheme(s, o, f, 3, 2), ref, o, f, "angle");
          }
  }

  TEST_CASE("cuda regularizers: host scheme on hard cases") {
    using namespace fused_cuda_test;
    const smg::RegularizerOptions o = options(smg::test::fused_all_terms());
    Flags f;
    SUBCASE("one frame: no pairs, no velocity: every energy 0") {
      const Case<double, std::int32_t> s(scene(1, 12, 4, 31));
      const auto ref = cpu(s, o, f);
      smg::RegularizerResult<double>::each_energy(
          [](const char* name, const smg::Accumulator<double>& e) {
            INFO(name);
            CHECK(double(e) == 0.0);
          },
          ref.e);
      check_same(host_scheme(s, o, f, 1, 1), ref, o, f, "T=1");
    }
    SUBCASE("T below the largest gap; K = 1") {
      const Case<double, std::int32_t> s(scene(3, 10, 1, 32));
      check_same(host_scheme(s, o, f, 1, 2), cpu(s, o, f), o, f, "T=3, K=1");
    }
    SUBCASE("an isolated node, zero weights, coincident nodes (zero-length edges)") {
      smg::test::Scene<double> sc = scene(7, 14, 5, 33);
      for (Index k = 0; k < sc.K; ++k) {
        sc.idx[static_cast<std::size_t>(4 * sc.K + k)] = -1;  // node 4: no out-edges
        sc.w[static_cast<std::size_t>(4 * sc.K + k)] = 0;
      }
      sc.w[static_cast<std::size_t>(2 * sc.K)] = 0;  // a zero-weight edge
      const Index j = sc.idx[static_cast<std::size_t>(6 * sc.K)];
      for (Index t = 0; t < sc.T; ++t) sc.set_pos(t, j, sc.pos(t, 6));  // edge 6 -> j has length 0
      const Case<double, std::int32_t> s(sc);
      const auto ref = cpu(s, o, f);
      check_same(host_scheme(s, o, f, 2, 3), ref, o, f, "hard");
      for (const double v : ref.gx) CHECK(std::isfinite(v));
    }
    SUBCASE("all confidences zero (nothing visible)") {
      smg::test::Scene<double> sc = scene(6, 11, 4, 34);
      std::fill(sc.v.begin(), sc.v.end(), std::uint8_t(0));
      const Case<double, std::int32_t> s(sc);
      check_same(host_scheme(s, o, f, 2, 2), cpu(s, o, f), o, f, "invisible");
    }
  }

  TEST_CASE("cuda regularizers: scratch within the inputs' bytes for long sequences") {
    using namespace fused_cuda_test;
    const smg::RegularizerOptions o = options(smg::test::fused_all_terms());
    for (const Index N : {Index(5000), Index(50000)}) {
      CAPTURE(N);
      const Index T = 400, K = 16;
      const std::size_t in = smg::detail::regularizer_input_bytes<float, std::int32_t>(T, N, K, true, true);
      const std::size_t extra = smg::cuda::regularizers_extra_bytes<float, std::int32_t>(
          T, N, K, o, true, true, true, true, false);
      CHECK(extra <= in);
      CHECK(extra > 0);
      const auto p = smg::cuda::detail::fused_plan<float, std::int32_t>(T, N, K, o, true, true, true,
                                                                        true, false);
      CHECK(p.lrm_chunk >= 2);  // more than one frame per launch at this size
      CHECK(p.conf_chunk >= p.lrm_chunk);
    }
    // Energies only: no per-edge scratch at all, so far fewer chunks.
    const auto e = smg::cuda::detail::fused_plan<float, std::int32_t>(400, 5000, 16, o, false,
                                                                      false, true, true, false);
    const auto g = smg::cuda::detail::fused_plan<float, std::int32_t>(400, 5000, 16, o, true,
                                                                      true, true, true, false);
    CHECK(e.lrm_chunk > 10 * g.lrm_chunk);
  }

  TEST_CASE("cuda regularizers: host-side argument checks name the argument") {
    using namespace fused_cuda_test;
    const Case<float, std::int32_t> s(scene(5, 9, 4, 41));
    smg::cuda::ReverseGraph rev;  // host-side checks read only its shape
    rev.nodes = s.N;
    rev.k = s.K;
    const smg::RegularizerOptions o = options(smg::test::fused_all_terms());
    auto msg = [](const smg::Status& st) { return std::string(st.message()); };
    CHECK(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
        s.positions(), s.rotations(), s.visibility(), s.graph(), o, rev));
    // Every term of the list has a CUDA pass (a phase of drive() or an Element), so the launcher
    // accepts all of them on: a term added to the list without one fails here.
    const smg::Status all = smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
        s.positions(), s.rotations(), s.visibility(), s.graph(), options(smg::test::fused_all_terms()), rev);
    CHECK_MESSAGE(all, all.message());
    CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                  s.positions(), smg::QuaternionsView<const float>(), s.visibility(), s.graph(), o,
                  rev))
              .rfind("rotations:", 0) == 0);
    smg::cuda::ReverseGraph other;
    other.nodes = s.N + 1;
    other.k = s.K;
    CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                  s.positions(), s.rotations(), s.visibility(), s.graph(), o, other))
              .rfind("reverse:", 0) == 0);
    std::vector<float> c(static_cast<std::size_t>(s.T * s.N));
    smg::RegularizerOptions no_conf = o;
    no_conf.terms.confidence = false;
    CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                  s.positions(), s.rotations(), s.visibility(), s.graph(), no_conf, rev,
                  smg::FrameScalarsView<float>(c.data(), s.T, s.N)))
              .rfind("confidence:", 0) == 0);
    std::vector<float> g(static_cast<std::size_t>((s.T + 1) * s.N * 3));
    CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                  s.positions(), s.rotations(), s.visibility(), s.graph(), o, rev, {},
                  smg::PositionsView<float>(g.data(), s.T + 1, s.N)))
              .rfind("grad_positions:", 0) == 0);
    // K above the most a CUDA kernel takes (the LRM kernel's kLrmMaxK): refused with every term
    // on, taken once the term that limits K is off; which term that is comes from the list (the
    // single-term removals that make it accepted), not from its name.
    const Index K = smg::cuda::kLrmMaxK + 1;
    std::vector<std::int32_t> idx(static_cast<std::size_t>(s.N * K), -1);
    std::vector<float> w(static_cast<std::size_t>(s.N * K), 0.f);
    const smg::NeighborsView<float, std::int32_t> wide(idx.data(), w.data(), s.N, K);
    smg::cuda::ReverseGraph rw;
    rw.nodes = s.N;
    rw.k = K;
    CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                  s.positions(), s.rotations(), s.visibility(), wide, o, rw))
              .rfind("graph:", 0) == 0);
    int limits_k = 0;
    for (unsigned k = 0; k < smg::test::fused_term_count(); ++k)
      if (smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
              s.positions(), s.rotations(), s.visibility(), wide, options(smg::test::fused_all_terms() & ~(1u << k)), rw))
        ++limits_k;
    CHECK(limits_k >= 1);
    // Every number of every term's options at NaN: refused before launch, naming the option.
    int numbers = 0;
    smg::for_each_term(o, [&](const char* term, bool, const auto& opts) {
      smg::for_each_option(opts, [&](const char* name, const auto& field) {
        if constexpr (std::is_same<std::decay_t<decltype(field)>, double>::value) {
          const std::string term_name = term, option = name;  // CAPTURE shows a char* as a pointer
          CAPTURE(term_name);
          CAPTURE(option);
          smg::RegularizerOptions bad = o;
          smg::for_each_term(bad, [&](const char* t, bool, auto& b) {
            smg::for_each_option(b, [&](const char* n, auto& g) {
              if constexpr (std::is_same<std::decay_t<decltype(g)>, double>::value)
                if (std::string(t) == term && std::string(n) == name) g = std::nan("");
            });
          });
          CHECK(msg(smg::cuda::validate_regularizers_shapes<float, std::int32_t>(
                        s.positions(), s.rotations(), s.visibility(), s.graph(), bad, rev))
                    .find(name) != std::string::npos);
          ++numbers;
        }
      });
    });
    CHECK(numbers > 0);
  }
}

// ---- On a GPU: the launcher against the CPU, and repeat runs bitwise. ----
namespace fused_cuda_test {

template <class S, class I>
Out<S> gpu(const Case<S, I>& s, const smg::RegularizerOptions& o, const Flags& f) {
  using smg::test::cuda::DeviceArray;
  Out<S> r = outputs<S>(s.T, s.N, f);
  const bool c_out = f.conf_out && o.terms.confidence;
  smg::test::cuda::Stream stream;
  DeviceArray<S> x(s.x), q(s.q), w(s.w), conf(r.conf), gx(r.gx), gr(r.gr);
  DeviceArray<I> idx(s.idx);
  DeviceArray<std::uint8_t> vis(s.v);
  DeviceArray<smg::RegularizerResult<S>> res;
  res.resize(1);
  smg::cuda::ReverseGraph rev;
  REQUIRE(smg::cuda::build_reverse_graph(idx.get(), s.N, s.K, stream.s, rev));
  const smg::NeighborsView<S, I> g(idx.get(), w.get(), s.N, s.K);
  const smg::RotationGradientView<S> grv = rotation_view(r.gr, s.T, s.N, f).empty()
      ? smg::RotationGradientView<S>()
      : f.raw ? smg::RotationGradientView<S>(smg::QuaternionsView<S>(gr.get(), s.T, s.N))
              : smg::RotationGradientView<S>(smg::TangentsView<S>(gr.get(), s.T, s.N));
  const smg::Status st = smg::cuda::regularizers<S, I>(
      smg::PositionsView<const S>(x.get(), s.T, s.N), smg::QuaternionsView<const S>(q.get(), s.T, s.N),
      f.vis ? smg::VisibilityView<const std::uint8_t>(vis.get(), s.T, s.N)
            : smg::VisibilityView<const std::uint8_t>(),
      g, o, rev, res.get(),
      c_out ? smg::FrameScalarsView<S>(conf.get(), s.T, s.N) : smg::FrameScalarsView<S>(),
      f.grad_x ? smg::PositionsView<S>(gx.get(), s.T, s.N) : smg::PositionsView<S>(),
      grv,
      stream.s);
  REQUIRE_MESSAGE(st, st.message());
  stream.sync();
  r.e = res.download()[0];
  r.conf = conf.download();
  r.gx = gx.download();
  r.gr = gr.download();
  return r;
}

// The masks the GPU runs, from the term list (no term named): every term, each term alone, each
// term with the confidences, and all terms but one.
inline std::vector<unsigned> list_masks() {
  const unsigned all = smg::test::fused_all_terms(), n = smg::test::fused_term_count();
  std::vector<unsigned> m{all};
  for (unsigned k = 0; k < n; ++k)
    for (const unsigned v : {1u << k, 1u | (1u << k), all & ~(1u << k)})
      if (v != 0 && std::find(m.begin(), m.end(), v) == m.end()) m.push_back(v);
  return m;
}

template <class S, class I>
void gpu_case(std::uint64_t seed, Index T, Index N, Index K) {
  CAPTURE(seed);
  CAPTURE(sizeof(S));
  const Case<S, I> s(scene(T, N, K, seed));
  each_mask_and_form(list_masks(), [&](const smg::RegularizerOptions& o, const Flags& f) {
    const Out<S> a = gpu(s, o, f);
    check_same(a, cpu(s, o, f), o, f, "gpu vs cpu", /*conf_bitwise=*/false);
    const Out<S> b = gpu(s, o, f);
    CHECK(std::memcmp(&a.e, &b.e, sizeof(a.e)) == 0);
    CHECK(std::memcmp(a.gx.data(), b.gx.data(), a.gx.size() * sizeof(S)) == 0);
    CHECK(std::memcmp(a.gr.data(), b.gr.data(), a.gr.size() * sizeof(S)) == 0);
  });
}

}  // namespace fused_cuda_test

TEST_CASE("cuda regularizers: GPU equals the CPU fused step; repeat runs bitwise") {
  using namespace fused_cuda_test;
  gpu_case<double, std::int32_t>(51, 14, 200, 8);
  gpu_case<double, std::int64_t>(52, 9, 150, 16);
  gpu_case<float, std::int32_t>(53, 20, 300, 16);
}

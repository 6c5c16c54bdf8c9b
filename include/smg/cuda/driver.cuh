// smg/cuda/driver.cuh — the CUDA regulariser driver: runs any subset of the terms of
// RegularizerOptions (node confidences (E2)-(E6), C-ARAP (E7)-(E10), plain ARAP, LRM (E11)-(E16),
// trajectory smoothness (E21)) with their gradients, deterministically (no float atomics, every
// sum in a fixed order), in three phases on one stream (docs/math/energy.md "The fused
// regulariser pass"):
//   1. confidences (when needed): per chunk of frames, the velocities (E1) and edge changes (E4)
//      of the chunk's frames, then c_{t,i} (E6) into [T][N] (the caller's output, or scratch);
//   2. the element terms in ONE pass, one thread per (frame t, node n): C-ARAP and ARAP
//      (cuda/rigid.cuh) and every term of the CPU list RegularizerTermSet (energy/term_list.hpp)
//      that has an Element, a step per (frame, node) without scratch (smoothness: AccelElement in
//      energy/terms/accel.hpp, the header of the CPU term), add what they owe to x_n^t's and
//      R_n^t's gradient rows, which only that thread writes; energies per thread, then per block
//      in a fixed tree, then over the blocks (deterministic_sum);
//   3. LRM (when on): per chunk of frames, the separate lrm kernels' per-element steps
//      (cuda/lrm.cuh: lrm_term_at, lrm_gather_at) and a velocity step that adds each chunk's
//      velocity parts to the frames they reach (one frame either side).
// The chunks bound the scratch: their length is the most frames whose scratch, with the [T][N]
// confidences, stays within the bytes of the inputs (fused_plan).
//
// The phases are written once, in drive(), over a Backend that only runs steps: DeviceBackend
// launches them as kernels (smg::cuda::regularizers), HostBackend runs them in host loops, so
// tests/cuda/test_cuda_regularizers.cu checks this very driver, its phase order, chunks and
// plan, against the CPU smg::regularizers() on machines without a GPU. A Backend has
//   Buffer<T>, allocate(Buffer<T>&, n)            scratch (device memory, or host memory)
//   items(f, items, frames, what)                 f(l, i) for every frame l < frames, item i
//   element_sums<S>(f, N, T, out)                 f(t, n, e[F::kEnergies]) for every (t, n);
//                                                 *out[k] = Σ e[k] for each non-null out[k]
//   sum(in, n, out, scale, accumulate, count, f)  deterministic_sum's contract
//   clear(result)                                 *result = {}
// Adding an element term needs no edit here: its CPU term (on the list RegularizerTermSet) names
// its host-device step, `using Element = ...; Element element() const;`, and its energy,
// `static Accumulator<S>& energy_of(RegularizerResult<S>&)` (AccelTerm is the example). The step
// has `SMG_HOST_DEVICE void at(t, n, x, conf, grad_x, S& energy) const` and
// `bool reads_confidence() const`; a step that reads the rotations (AngleElement) says so with
// `static constexpr bool kReadsRotations = true` and takes q and the rotation gradient rows too,
// `at(t, n, x, q, conf, grad_x, grad_tangent, grad_raw, S& energy)`. The list is read on the host: a term's Element is configured
// there (RegularizerTermSet's constructor, with edges = N·K, so a step must not scale by the
// graph's edge count, which only the device knows).
#pragma once

#include "smg/cuda/common.cuh"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "smg/core/views.hpp"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/cuda/rigid.cuh"
#include "smg/energy/block.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/term_list.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {
namespace detail {

// ---- The element terms of the CPU list: the members of RegularizerTermSet with an Element ----

// What an Element reads (ElementReadsRotations, ElementReadsGraph) is stated once, in
// energy/block.hpp, beside the term concept: the CPU element pass (energy/element_pass.hpp)
// reads the same traits.
using ::smg::detail::ElementReadsGraph;
using ::smg::detail::ElementReadsRotations;

// The steps of the element terms, in list order; at() runs those that are on, term k's energy
// into e[k]. A recursive pack rather than std::tuple: device code calls it.

template <class... Es>
struct ElementPack {
  static constexpr int size = 0;
  template <class S, class I>
  SMG_HOST_DEVICE void at(Index, Index, PositionsView<const S>, QuaternionsView<const S>, const S*,
                          const smg::detail::ElementGraph<S, I>&, S*, S*, S*, S*) const {}
  bool any_on() const { return false; }
  bool reads_confidence() const { return false; }
  bool reads_rotations() const { return false; }
};
template <class E, class... Es>
struct ElementPack<E, Es...> {
  static constexpr int size = 1 + sizeof...(Es);
  bool on = false;
  E step;
  ElementPack<Es...> rest;
  template <class S, class I>
  SMG_HOST_DEVICE void at(Index t, Index n, PositionsView<const S> x, QuaternionsView<const S> q,
                          const S* conf, const smg::detail::ElementGraph<S, I>& eg, S* grad_x, S* grad_tangent,
                          S* grad_raw, S* e) const {
    if constexpr (ElementReadsGraph<E>::value) {
      if (on) step.at(t, n, q, eg, grad_tangent, grad_raw, e[0]);
    } else if constexpr (ElementReadsRotations<E>::value) {
      if (on) step.at(t, n, x, q, conf, grad_x, grad_tangent, grad_raw, e[0]);
    } else {
      if (on) step.at(t, n, x, conf, grad_x, e[0]);
    }
    rest.at(t, n, x, q, conf, eg, grad_x, grad_tangent, grad_raw, e + 1);
  }
  bool any_on() const { return on || rest.any_on(); }
  bool reads_confidence() const { return (on && step.reads_confidence()) || rest.reads_confidence(); }
  bool reads_rotations() const {
    return (on && (ElementReadsRotations<E>::value || ElementReadsGraph<E>::value)) ||
           rest.reads_rotations();
  }
};

// ElementPack of the Elements of Ts (in order), skipping the terms without one.
template <class Pack, class... Ts>
struct ElementsOf {
  using type = Pack;
};
template <bool Has, class Pack, class T>
struct AppendElement {
  using type = Pack;
};
template <class... Es, class T>
struct AppendElement<true, ElementPack<Es...>, T> {
  using type = ElementPack<Es..., typename T::Element>;
};
template <class Pack, class T, class... Ts>
struct ElementsOf<Pack, T, Ts...> {
  using type = typename ElementsOf<typename AppendElement<smg::detail::has_element_v<T>, Pack, T>::type,
                                   Ts...>::type;
};
// The list's member types, as apply() passes them.
struct TermTypes {
  template <class... Ts>
  ElementsOf<ElementPack<>, std::decay_t<Ts>...> operator()(Ts&...) const;
};
template <class S, class I>
using ListElements = typename decltype(std::declval<smg::detail::RegularizerTermSet<S, I>&>().apply(
    TermTypes{}))::type;

// Fills the pack from the configured terms (host values).
template <class Pack>
void fill_elements(Pack&) {}
template <class Pack, class T, class... Ts>
void fill_elements(Pack& p, const T& t, const Ts&... ts) {
  if constexpr (smg::detail::has_element_v<T>) {
    p.on = t.on();
    p.step = t.element();
    fill_elements(p.rest, ts...);
  } else {
    fill_elements(p, ts...);
  }
}

// The energies of the list's element terms, in pack order (null for a term that is off).
template <class S, class Pack>
void element_energy_slots(Accumulator<S>**, RegularizerResult<S>*, const Pack&) {}
template <class S, class Pack, class T, class... Ts>
void element_energy_slots(Accumulator<S>** out, RegularizerResult<S>* r, const Pack& p, const T&,
                          const Ts&... ts) {
  if constexpr (smg::detail::has_element_v<T>) {
    *out = p.on ? &T::energy_of(*r) : nullptr;
    element_energy_slots<S>(out + 1, r, p.rest, ts...);
  } else {
    element_energy_slots<S>(out, r, p, ts...);
  }
}

// The element pack of `o` over T frames, N nodes (host values, as the CPU list configures them).
template <class S, class I>
ListElements<S, I> list_elements(const RegularizerOptions& o, Index T, Index N, Index K, bool want_x,
                                 bool want_r) {
  smg::detail::RegularizerTermSet<S, I> set(T, N, K, N * K, o, want_x, want_r);
  ListElements<S, I> pack;
  set.apply([&](const auto&... t) { fill_elements(pack, t...); });
  return pack;
}

// The terms drive() runs in a phase of their own (confidences, LRM) or by hand in the element
// pass (C-ARAP and ARAP); every other term of the list runs only through its Element.
template <class T>
struct OwnPhase : std::false_type {};
template <class S, class I>
struct OwnPhase<smg::detail::ConfidenceTerm<S, I>> : std::true_type {};
template <class S, class I>
struct OwnPhase<smg::detail::RigidTerm<S, I>> : std::true_type {};
template <class S, class I>
struct OwnPhase<smg::detail::LrmTerm<S, I>> : std::true_type {};
template <class T>
constexpr bool kRunsOnCuda = OwnPhase<T>::value || smg::detail::has_element_v<T>;

// Whether drive() runs every term of `o` that is on: a CPU term with neither a phase here nor an
// Element would be left out of the GPU's energies and gradients, silently. Each term is
// configured alone (on shapes where every term with an effect is on); one line naming the first
// term without a CUDA pass.
template <class S, class I>
Status check_cuda_terms(const RegularizerOptions& o) {
  Status st = Status::ok();
  for_each_term(o, [&](const char* name, bool on, const auto&) {
    if (!on || !st) return;
    RegularizerOptions alone = o;
    for_each_term(alone, [&](const char* n, bool& f, const auto&) { f = std::string(n) == name; });
    smg::detail::RegularizerTermSet<S, I> set(64, 8, 4, 32, alone, true, true);
    bool missing = false;
    set.apply([&](const auto&... t) {
      ((missing = missing || (t.on() && !kRunsOnCuda<std::decay_t<decltype(t)>>)), ...);
    });
    if (missing)
      st = Status::error(std::string("options.terms.") + name +
                         ": smg::cuda::regularizers has no pass for this term (its term struct "
                         "names no Element, cuda/driver.cuh)");
  });
  return st;
}

// Energies of the element pass, in this order: C-ARAP, ARAP, then the list's element terms.
template <class S, class I>
constexpr int kElementEnergies = 2 + ListElements<S, I>::size;

// The plan of one call (host): which phases run, the chunk lengths, the scratch.
struct FusedPlan {
  bool confidence = false, rigid = false, lrm = false;
  bool elements = false;  // a term of the list's element pass is on
  bool want_x = false, want_r = false;
  bool conf_scratch = false;  // c [T][N] in scratch (no caller output)
  Index conf_chunk = 1, lrm_chunk = 1;
  std::size_t extra_bytes = 0;  // peak scratch bytes
};

template <class S, class I>
FusedPlan fused_plan(Index T, Index N, Index K, const RegularizerOptions& o, bool want_x,
                     bool want_r, bool rotations, bool visibility, bool conf_out) {
  using Acc = Accumulator<S>;
  FusedPlan p;
  const RegularizerTerms& on = o.terms;
  bool any_gap = false;
  for (const auto& [listed, list] : {std::pair{on.carap, &o.carap.gaps}, std::pair{on.arap, &o.arap.gaps}})
    if (listed)
      for (const Gap& g : *list) any_gap = any_gap || (g.delta >= 1 && g.delta < T && g.weight != 0.0);
  p.rigid = any_gap && K > 0;
  p.lrm = on.lrm && K > 0;
  const ListElements<S, I> elements = list_elements<S, I>(o, T, N, K, want_x, want_r);
  p.elements = elements.any_on();
  p.confidence = on.confidence && (conf_out || p.rigid || p.lrm || elements.reads_confidence());
  p.want_x = want_x && (p.rigid || p.lrm || p.elements);
  p.want_r = want_r && (p.rigid || elements.reads_rotations());
  p.conf_scratch = p.confidence && !conf_out;
  if (T == 0 || N == 0) return p;
  const std::size_t bound =
      smg::detail::regularizer_input_bytes<S, I>(T, N, K, rotations, visibility);
  std::size_t fixed = p.conf_scratch ? sizeof(S) * static_cast<std::size_t>(T * N) : 0;
  if (p.confidence) fixed += sizeof(S) * static_cast<std::size_t>(N);  // 1/Σw
  // Energy partials: the element pass's blocks, and deterministic_sum's.
  const std::size_t blocks =
      static_cast<std::size_t>(grid_for(N)) * std::min<Index>(T, 65535);
  if (p.rigid || p.elements) fixed += kElementEnergies<S, I> * blocks * sizeof(Acc);
  fixed += kSumBlocks * sizeof(Acc);
  const std::size_t left = bound > fixed ? bound - fixed : 0;
  auto frames_within = [&](std::size_t per_frame) {
    const Index f = per_frame > 0 ? static_cast<Index>(left / per_frame) : T;
    return std::max<Index>(1, std::min<Index>(T, f));
  };
  std::size_t peak = 0;
  if (p.confidence) {
    const std::size_t per = sizeof(S) * static_cast<std::size_t>(4 * N);
    p.conf_chunk = frames_within(per);
    peak = std::max(peak, per * static_cast<std::size_t>(p.conf_chunk));
  }
  if (p.lrm) {
    std::size_t per = sizeof(Acc) * static_cast<std::size_t>(N);
    if (p.want_x) per += sizeof(S) * static_cast<std::size_t>(6 * N * K + 6 * N);
    p.lrm_chunk = frames_within(per);
    peak = std::max(peak, per * static_cast<std::size_t>(p.lrm_chunk));
  }
  p.extra_bytes = fixed + peak;
  return p;
}

// LRM's kernel arguments for a call over T frames (as cuda::lrm forms them); edge_count as above.
template <class S>
LrmKernelArgs<S> fused_lrm_args(const RegularizerOptions& o, Index T, bool gradient,
                                const std::int32_t* edge_count) {
  using L = Literal<S>;
  LrmKernelArgs<S> args;
  args.p = smg::detail::lrm_params<S>(o.lrm, gradient);
  args.alpha = L(o.lrm.alpha);
  args.scale = L(o.lrm.weight);
  args.weight = o.lrm.weight;
  args.frames = T;
  args.edge_count = o.lrm.normalization == Normalization::mean ? edge_count : nullptr;
  return args;
}

// ---- The steps: plain values with a host-device call operator (a kernel takes them by value,
// a host loop calls them; no extended lambdas, so every nvcc build compiles them). ----

template <class S, class I>
struct InverseRowWeightStep {
  NeighborsView<S, I> graph;
  S* inv_w;
  SMG_HOST_DEVICE void operator()(Index, Index i) const { inv_w[i] = inverse_row_weight(graph, i); }
};

template <class S, class I>
struct ConfidenceInputsStep {
  Index c0;
  PositionsView<const S> x;
  NeighborsView<S, I> graph;
  const S* inv_w;
  S *u, *e;
  SMG_HOST_DEVICE void operator()(Index l, Index i) const {
    confidence_inputs_at(l, i, c0, x, graph, inv_w, u, e);
  }
};

template <class S, class I>
struct ConfidenceStep {
  Index c0;
  NeighborsView<S, I> graph;
  const S *inv_w, *u, *e;
  ConfidenceConstants<S> p;
  const std::uint8_t* visibility;
  S* conf;
  SMG_HOST_DEVICE void operator()(Index l, Index i) const {
    confidence_at(l, i, c0, graph, inv_w, u, e, p, visibility, conf, static_cast<S*>(nullptr),
                  static_cast<S*>(nullptr));
  }
};

// Phase 2's element (t, n): every element term that is on. e[kEnergies] receives the energies
// of the terms this element owns (C-ARAP, ARAP, then the list's element terms).
template <class S, class I>
struct ElementTerms {
  static constexpr int kEnergies = kElementEnergies<S, I>;
  bool rigid = false;
  FusedRigidConstants<S> rigid_constants;
  ListElements<S, I> elements;
  PositionsView<const S> x;
  QuaternionsView<const S> q;
  const S* conf = nullptr;  // c [T][N], or null (c ≡ 1)
  NeighborsView<S, I> graph;
  const std::int32_t* rev_offsets = nullptr;
  const std::int64_t* rev_entries = nullptr;
  S *grad_x = nullptr, *grad_tangent = nullptr, *grad_raw = nullptr;

  SMG_HOST_DEVICE void operator()(Index t, Index n, S* e) const {
    if (rigid)
      fused_rigid_node_at(t, n, rigid_constants, x, q, conf, graph, rev_offsets, rev_entries,
                          grad_x, grad_tangent, grad_raw, e);
    elements.at(t, n, x, q, conf, smg::detail::ElementGraph<S, I>{graph, rev_offsets, rev_entries}, grad_x,
                grad_tangent, grad_raw, e + 2);
  }
};

// KMax sizes lrm_term_at's local arrays (8, 16 or 32), picked at launch from K as cuda::lrm
// does: a runtime choice inside one kernel would give every K the 32-entry stack frame.
template <class S, class I, int KMax>
struct LrmTermStep {
  Index c0;
  PositionsView<const S> x;
  FrameScalarsView<const S> conf;
  NeighborsView<S, I> graph;
  LrmKernelArgs<S> args;
  Accumulator<S>* terms;
  S *gx_edges, *gu_edges;
  SMG_HOST_DEVICE void operator()(Index l, Index i) const {
    const Index base = c0 * x.nodes();
    lrm_term_at<S, I, KMax>(base + l * x.nodes() + i, x, conf, graph, args, terms, gx_edges,
                            gu_edges, {}, base);
  }
};

template <class S>
struct LrmGatherStep {
  Index N, K;
  const std::int32_t* offsets;
  const std::int64_t* entries;
  const S *gx_edges, *gu_edges;
  S *gx_nodes, *gu_nodes;
  SMG_HOST_DEVICE void operator()(Index l, Index i) const {
    lrm_gather_at(l * N + i, N, K, offsets, entries, gx_edges, gu_edges, gx_nodes, gu_nodes);
  }
};

template <class S>
struct LrmVelocityStep {
  Index s0, c0, c1, T, N;
  const S *gx_nodes, *gu_nodes;
  PositionsView<S> grad;
  SMG_HOST_DEVICE void operator()(Index l, Index j) const {
    lrm_velocity_chunk_at(s0 + l, j, c0, c1, T, N, gx_nodes, gu_nodes, grad);
  }
};

// ---- Backends ----

template <class F>
__global__ void items_kernel(F f, Index items, Index frames) {
  const int i = frame_item(items);
  if (i < 0) return;
  SMG_CUDA_FOR_FRAMES(l, frames) f(l, Index(i));
}

// One thread per node, frames along y; per-block energy partials [F::kEnergies][blocks], each the
// block's fixed tree sum of its threads' sums.
template <class S, class F>
__global__ void element_sums_kernel(F f, Index N, Index T, Accumulator<S>* partials) {
  using Acc = Accumulator<S>;
  __shared__ Acc shared[kThreads];
  const int n = frame_item(N);
  Acc sum[F::kEnergies];
  for (Acc& v : sum) v = Acc(0);
  SMG_CUDA_FOR_FRAMES(t, T) {
    if (n < 0) continue;
    S e[F::kEnergies];
    for (S& v : e) v = S(0);
    f(t, Index(n), e);
    for (int k = 0; k < F::kEnergies; ++k) sum[k] += Acc(e[k]);
  }
  const unsigned blocks = gridDim.x * gridDim.y, block = blockIdx.y * gridDim.x + blockIdx.x;
  for (int k = 0; k < F::kEnergies; ++k) {
    const Acc s = block_tree_sum(sum[k], shared);
    if (threadIdx.x == 0) partials[k * blocks + block] = s;
    __syncthreads();  // every thread has read shared[0] before the next sum overwrites it
  }
}

// Kernels on `stream` (what smg::cuda::regularizers runs).
struct DeviceBackend {
  cudaStream_t stream = nullptr;

  template <class T>
  using Buffer = DeviceBuffer<T>;
  template <class T>
  Status allocate(Buffer<T>& b, std::size_t n) const {
    return b.allocate(n, stream);
  }
  template <class F>
  Status items(const F& f, Index items, Index frames, const char* what) const {
    if (items <= 0 || frames <= 0) return Status::ok();
    items_kernel<F><<<frame_grid(items, frames), kThreads, 0, stream>>>(f, items, frames);
    SMG_CUDA_TRY(cudaGetLastError(), what);
    return Status::ok();
  }
  template <class S, class F>
  Status element_sums(const F& f, Index N, Index T, Accumulator<S>* const* out) const {
    using Acc = Accumulator<S>;
    const dim3 grid = frame_grid(N, T);
    const Index blocks = static_cast<Index>(grid.x) * grid.y;
    DeviceBuffer<Acc> partials;
    if (Status s = partials.allocate(static_cast<std::size_t>(F::kEnergies * blocks), stream); !s)
      return s;
    element_sums_kernel<S, F><<<grid, kThreads, 0, stream>>>(f, N, T, partials.get());
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::regularizers: element kernel launch");
    for (int k = 0; k < F::kEnergies; ++k)
      if (out[k] != nullptr)
        if (Status s = deterministic_sum(partials.get() + k * blocks, blocks, out[k], stream); !s)
          return s;
    return Status::ok();
  }
  template <class In, class T>
  Status sum(const In* in, Index n, T* out, T scale, bool accumulate, const std::int32_t* count,
             Index count_factor) const {
    return deterministic_sum(in, n, out, stream, scale, accumulate, count, count_factor);
  }
  template <class S>
  Status clear(RegularizerResult<S>* r) const {
    SMG_CUDA_TRY(cudaMemsetAsync(r, 0, sizeof(RegularizerResult<S>), stream),
                 "smg::cuda::regularizers: result");
    return Status::ok();
  }
};

// Host loops over the same steps, one at a time (the CUDA host suite runs the driver through
// this on machines without a GPU). Scratch starts as NaN (or −7), as device scratch starts with
// whatever was there: a step that read what no step wrote would show in the results.
struct HostBackend {
  template <class T>
  struct Buffer {
    std::vector<T> v;
    T* get() { return v.empty() ? nullptr : v.data(); }
  };
  template <class T>
  Status allocate(Buffer<T>& b, std::size_t n) const {
    if constexpr (std::is_floating_point_v<T>)
      b.v.assign(n, std::numeric_limits<T>::quiet_NaN());
    else
      b.v.assign(n, T(-7));
    return Status::ok();
  }
  template <class F>
  Status items(const F& f, Index items, Index frames, const char*) const {
    for (Index l = 0; l < frames; ++l)
      for (Index i = 0; i < items; ++i) f(l, i);
    return Status::ok();
  }
  template <class S, class F>
  Status element_sums(const F& f, Index N, Index T, Accumulator<S>* const* out) const {
    using Acc = Accumulator<S>;
    Acc sum[F::kEnergies];
    for (Acc& v : sum) v = Acc(0);
    for (Index t = 0; t < T; ++t)
      for (Index n = 0; n < N; ++n) {
        S e[F::kEnergies];
        for (S& v : e) v = S(0);
        f(t, n, e);
        for (int k = 0; k < F::kEnergies; ++k) sum[k] += Acc(e[k]);
      }
    for (int k = 0; k < F::kEnergies; ++k)
      if (out[k] != nullptr) *out[k] = sum[k];
    return Status::ok();
  }
  template <class In, class T>
  Status sum(const In* in, Index n, T* out, T scale, bool accumulate, const std::int32_t* count,
             Index count_factor) const {
    T v(0);
    for (Index k = 0; k < n; ++k) v += static_cast<T>(in[k]);
    double sc = static_cast<double>(scale);
    if (count != nullptr) sc = scale_over_count(sc, count_factor, count);  // as sum_final_kernel
    const T s = v * static_cast<T>(sc);
    *out = accumulate ? *out + s : s;
    return Status::ok();
  }
  template <class S>
  Status clear(RegularizerResult<S>* r) const {
    *r = RegularizerResult<S>();
    return Status::ok();
  }
};

// ---- The driver ----

// Every phase of one call, through `be`. Views and pointers are in the backend's memory (device
// memory for DeviceBackend): positions [T][N][3], rotations [T][N][4] (with a term that reads
// them: C-ARAP, ARAP, angle),
// visibility [T][N] or empty, graph [N][K]; rev_offsets [N + 1] and rev_entries: the graph's
// in-edges (ReverseGraph), edge_count = &rev_offsets[N]; result: overwritten; confidence,
// grad_positions, grad_rotations: as smg::cuda::regularizers. `p` is fused_plan's for these
// shapes (a test may shorten its chunks). Shapes and options are the caller's to check.
template <class S, class I, class Backend>
Status drive(const Backend& be, const FusedPlan& p, const RegularizerOptions& o,
             PositionsView<const S> positions, QuaternionsView<const S> rotations,
             VisibilityView<const std::uint8_t> visibility, const NeighborsView<S, I>& graph,
             const std::int32_t* rev_offsets, const std::int64_t* rev_entries,
             const std::int32_t* edge_count, RegularizerResult<S>* result,
             FrameScalarsView<S> confidence, PositionsView<S> grad_positions,
             RotationGradientView<S> grad_rotations) {
  using Acc = Accumulator<S>;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  if (Status s = be.clear(result); !s) return s;
  if (T == 0 || N == 0 || !(p.confidence || p.rigid || p.lrm || p.elements)) return Status::ok();
  if (Status s = check_frame_items(N, "positions"); !s) return s;

  // Phase 1: confidences into the caller's output or [T][N] scratch.
  typename Backend::template Buffer<S> conf_buf;
  S* conf = confidence.data();
  if (p.conf_scratch) {
    if (Status s = be.allocate(conf_buf, static_cast<std::size_t>(T * N)); !s) return s;
    conf = conf_buf.get();
  }
  if (p.confidence) {
    typename Backend::template Buffer<S> inv_w, u, e;
    if (Status s = be.allocate(inv_w, static_cast<std::size_t>(N)); !s) return s;
    if (Status s = be.allocate(u, static_cast<std::size_t>(3 * N * p.conf_chunk)); !s) return s;
    if (Status s = be.allocate(e, static_cast<std::size_t>(N * p.conf_chunk)); !s) return s;
    const char* what = "smg::cuda::regularizers: confidence kernel launch";
    if (Status s = be.items(InverseRowWeightStep<S, I>{graph, inv_w.get()}, N, 1, what); !s)
      return s;
    for (Index c0 = 0; c0 < T; c0 += p.conf_chunk) {
      const Index nf = std::min(p.conf_chunk, T - c0);
      const ConfidenceInputsStep<S, I> in{c0, positions, graph, inv_w.get(), u.get(), e.get()};
      if (Status s = be.items(in, N, nf, what); !s) return s;
      const ConfidenceStep<S, I> cs{c0, graph, inv_w.get(), u.get(), e.get(),
                                    ConfidenceConstants<S>(o.confidence), visibility.data(), conf};
      if (Status s = be.items(cs, N, nf, what); !s) return s;
    }
  }
  const S* conf_in = p.confidence ? conf : nullptr;
  S* const gx = p.want_x ? grad_positions.data() : nullptr;

  // Phase 2: the element terms (C-ARAP, ARAP, the list's element terms) in one pass, no
  // per-edge scratch.
  if (p.rigid || p.elements) {
    using F = ElementTerms<S, I>;
    F f;
    f.rigid = p.rigid;
    if (p.rigid) f.rigid_constants = fused_rigid_constants<S>(o, T, edge_count);
    smg::detail::RegularizerTermSet<S, I> set(T, N, K, N * K, o, p.want_x, p.want_r);
    Acc* out[F::kEnergies] = {p.rigid ? &result->carap : nullptr, p.rigid ? &result->arap : nullptr};
    set.apply([&](const auto&... t) {
      fill_elements(f.elements, t...);
      element_energy_slots<S>(out + 2, result, f.elements, t...);
    });
    f.x = positions;
    f.q = rotations;
    f.conf = conf_in;
    f.graph = graph;
    f.rev_offsets = rev_offsets;
    f.rev_entries = rev_entries;
    f.grad_x = gx;
    if (p.want_r) {
      f.grad_tangent = grad_rotations.is_raw() ? nullptr : grad_rotations.tangent().data();
      f.grad_raw = grad_rotations.is_raw() ? grad_rotations.raw().data() : nullptr;
    }
    if (Status s = be.template element_sums<S>(f, N, T, out); !s) return s;
  }

  // Phase 3: LRM by chunks of frames.
  if (p.lrm) {
    const bool mean = o.lrm.normalization == Normalization::mean;
    const LrmKernelArgs<S> args = fused_lrm_args<S>(o, T, p.want_x, edge_count);
    const Index chunk = p.lrm_chunk;
    typename Backend::template Buffer<Acc> terms;
    typename Backend::template Buffer<S> edges, nodes;
    if (Status s = be.allocate(terms, static_cast<std::size_t>(N * chunk)); !s) return s;
    if (p.want_x) {
      if (Status s = be.allocate(edges, static_cast<std::size_t>(6 * N * K * chunk)); !s) return s;
      if (Status s = be.allocate(nodes, static_cast<std::size_t>(6 * N * chunk)); !s) return s;
    }
    const FrameScalarsView<const S> cv =
        conf_in ? FrameScalarsView<const S>(conf_in, T, N) : FrameScalarsView<const S>();
    const char* what = "smg::cuda::regularizers: LRM kernel launch";
    for (Index c0 = 0; c0 < T; c0 += chunk) {
      const Index nf = std::min(chunk, T - c0), c1 = c0 + nf, n = nf * N;
      S* gxe = edges.get();
      S* gue = gxe ? gxe + 3 * n * K : nullptr;
      Status st;
      if (K <= 8)
        st = be.items(LrmTermStep<S, I, 8>{c0, positions, cv, graph, args, terms.get(), gxe, gue}, N, nf, what);
      else if (K <= 16)
        st = be.items(LrmTermStep<S, I, 16>{c0, positions, cv, graph, args, terms.get(), gxe, gue}, N, nf, what);
      else
        st = be.items(LrmTermStep<S, I, 32>{c0, positions, cv, graph, args, terms.get(), gxe, gue}, N, nf, what);
      if (!st) return st;
      if (Status s = be.sum(terms.get(), n, &result->lrm, Acc(o.lrm.weight), c0 > 0,
                            mean ? edge_count : nullptr, T);
          !s)
        return s;
      if (!p.want_x) continue;
      S* gxn = nodes.get();
      S* gun = gxn + 3 * n;
      if (Status s = be.items(LrmGatherStep<S>{N, K, rev_offsets, rev_entries, gxe, gue, gxn, gun},
                              N, nf, what);
          !s)
        return s;
      const Index s0 = c0 > 0 ? c0 - 1 : 0, s1 = std::min(T, c1 + 1);
      if (Status s = be.items(LrmVelocityStep<S>{s0, c0, c1, T, N, gxn, gun, grad_positions}, N,
                              s1 - s0, what);
          !s)
        return s;
    }
  }
  return Status::ok();
}

}  // namespace detail
}  // namespace smg::cuda

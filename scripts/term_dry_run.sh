#!/usr/bin/env bash
# scripts/term_dry_run.sh — a dry run of docs/contributing.md section 3 ("Adding a regulariser
# term, step by step"; issue 45, step 5): in a temporary git worktree of HEAD it writes a
# throwaway term `dryrun` from the templates below (a header in energy/terms/ with a CUDA
# Element, its one-term call, its equations page, its options struct with an enum option `form`
# of a new enum and a scalar `weight`), makes the checklist's edits of existing files by anchors,
# regenerates the docs' terms table, builds the term-list checks (test_energy, test_api,
# smg_cli) and runs the tests that iterate the list, then prints the files it had to create and
# edit (git status against HEAD) with their counts and each check's result, and removes
# everything it made. Exit 0 only when every check passes; 2 when it refuses to start.
#
# The same build and tests run first on HEAD without the term (the baseline), so that the counts
# printed for each test show what the term added; `-s` logs show it named (captured labels,
# smg_cli flags). Why: the section claims a number of files a new term touches; this measures it
# on the current tree, and fails when an edit the section does not list becomes necessary (a
# check fails). CI does not run it: it builds test_energy, test_api and smg_cli twice from
# scratch (about 10 minutes at -j1).
#
#   scripts/term_dry_run.sh                 run it (the caller's tree must be clean: it is never
#                                           written; the work happens in a worktree under $TMPDIR)
#   SMG_DRY_RUN_JOBS=N                      build parallelism (default 1)
#   SMG_DRY_RUN_BASELINE=0                  skip the baseline (half the time; no "without" counts)
#   SMG_DRY_RUN_CUDA=1                      also build and run the CUDA host suite
#                                           (test_cuda -ts=cuda-host; needs nvcc, slow)
#   SMG_DRY_RUN_KEEP=1                      keep the worktree and build for inspection (prints
#                                           where; remove it with `git worktree remove --force`)
set -euo pipefail

ROOT=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
cd "$ROOT"
JOBS=${SMG_DRY_RUN_JOBS:-1}
START=$(date +%s)

if [ -n "$(git status --porcelain)" ]; then
  echo "term_dry_run: the working tree has changes; commit or stash them first (nothing done)" >&2
  git status --short >&2
  exit 2
fi
if [ -e include/smg/energy/terms/dryrun.hpp ]; then
  echo "term_dry_run: include/smg/energy/terms/dryrun.hpp exists; the dry run needs the name" >&2
  exit 2
fi

TMP=$(mktemp -d "${TMPDIR:-/tmp}/smg-term-dry-run.XXXXXX")
WT="$TMP/src"
cleanup() {
  local rc=$?
  if [ "${SMG_DRY_RUN_KEEP:-0}" = 1 ]; then
    echo "term_dry_run: kept $WT (git worktree remove --force $WT; rm -rf $TMP)"
  else
    git -C "$ROOT" worktree remove --force "$WT" >/dev/null 2>&1 || true
    rm -rf "$TMP"
    git -C "$ROOT" worktree prune >/dev/null 2>&1 || true
  fi
  exit $rc
}
trap cleanup EXIT
trap 'exit 130' INT TERM
git worktree add --quiet --detach "$WT" HEAD
cd "$WT"
echo "term_dry_run: base $(git rev-parse --short HEAD), worktree $WT"

# ---- The checks (run on HEAD for the baseline, then with the term) ----------------------------

declare -a NAMES=() RESULTS=()
check() {  # check NAME COMMAND...: run it, record PASS/FAIL
  local name=$1
  shift
  echo "== $name"
  if "$@"; then RESULTS+=("PASS"); else RESULTS+=("FAIL"); fi
  NAMES+=("$name")
}

BUILD="$WT/build/dry"
configure() {
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON -DSMG_BUILD_TESTS=ON \
    -DSMG_BUILD_EXAMPLES=ON -DSMG_BUILD_BENCH=OFF -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=OFF \
    >"$TMP/configure.log" 2>&1 || { tail -30 "$TMP/configure.log"; return 1; }
}
build() {
  cmake --build "$BUILD" -j "$JOBS" --target smg_cli test_energy test_api >"$TMP/build.log" 2>&1 \
    || { grep -E "error|Error" "$TMP/build.log" | head -40; tail -3 "$TMP/build.log"; return 1; }
}
# The list-driven tests; -s reports every assertion with what it logged (for_each_option_variant's
# label "dryrun.form=quartic", smg_cli's "--terms dryrun" and its flags), so the lines naming
# `dryrun` show that the new term is exercised (doctest prints the operators' CAPTURE(Op::name)
# as an address: the generic operator tests show it in the counts only).
doctest_run() {  # doctest_run LOG BINARY ARGS...
  local log=$1 bin=$2
  shift 2
  "$BUILD/tests/$bin" "$@" -s -nv >"$log" 2>&1
  local rc=$?
  echo "  $bin: $(counts "$log") ($(counts "$TMP/base-$bin.log") without the term);" \
    "lines of its -s report naming dryrun: $(grep -c dryrun "$log" || true)"
  [ $rc = 0 ] || grep -B2 -A12 "ERROR" "$log" | head -60
  return $rc
}
ENERGY_FILTER="-tc=*every*,smg_cli regularizers*"
energy_tests() { doctest_run "$TMP/test_energy.log" test_energy "$ENERGY_FILTER"; }
api_tests() { doctest_run "$TMP/test_api.log" test_api; }
# "N cases, M assertions passed" from a doctest log; "not run" without one.
counts() {
  [ -f "$1" ] || { echo "not run"; return; }
  local c a
  c=$(sed -n 's/^\[doctest\] test cases: *\([0-9]*\) |.*/\1/p' "$1")
  a=$(sed -n 's/^\[doctest\] assertions: *[0-9]* | *\([0-9]*\) passed.*/\1/p' "$1")
  echo "$c cases, $a assertions passed"
}
# The same tests on HEAD, before the term is written: the counts the term adds.
baseline() {
  build || return 1
  "$BUILD/tests/test_energy" "$ENERGY_FILTER" -nv >"$TMP/base-test_energy.log" 2>&1 &&
    "$BUILD/tests/test_api" -nv >"$TMP/base-test_api.log" 2>&1 || return 1
  echo "  test_energy: $(counts "$TMP/base-test_energy.log"); test_api: $(counts "$TMP/base-test_api.log")"
}
cli_help() {
  local help
  help=$("$BUILD/examples/smg_cli" regularizers --help 2>&1) || true
  echo "$help" | grep -E "dryrun" | sed 's/^/  /'
  echo "$help" | grep -q -- "--dryrun-form" && echo "$help" | grep -q -- "--dryrun-weight"
}
# The Element is compiled only by nvcc in the tree (the CUDA host suite); here g++ instantiates
# it and checks it against the CPU term: the sums over (t, i) of at() equal dryrun()'s energy and
# gradient, for both forms.
element_host() {
  cat >"$TMP/element_check.cpp" <<'EOF'
#include <cmath>
#include <cstdio>
#include <vector>

#include "smg/energy.hpp"

int main() {
  const smg::Index T = 6, N = 5;
  std::vector<double> x(T * N * 3);
  for (std::size_t k = 0; k < x.size(); ++k) x[k] = std::sin(0.7 * double(k)) + 0.01 * double(k);
  const smg::PositionsView<const double> X(x.data(), T, N);
  int bad = 0;
  for (smg::DryrunForm form : smg::kDryrunForms) {
    smg::DryrunOptions o;
    o.form = form;
    o.weight = 0.5;
    std::vector<double> g_cpu(x.size(), 0.0), g_el(x.size(), 0.0);
    const double e_cpu = smg::dryrun<double>(X, o, smg::PositionsView<double>(g_cpu.data(), T, N));
    smg::detail::DryrunTerm<double, std::int32_t> term;
    term.configure(o, T, N);
    const auto el = term.element();
    double e_el = 0;
    for (smg::Index t = 0; t < T; ++t)
      for (smg::Index i = 0; i < N; ++i) el.at(t, i, X, nullptr, g_el.data(), e_el);
    double dg = 0;
    for (std::size_t k = 0; k < x.size(); ++k) dg = std::fmax(dg, std::fabs(g_el[k] - g_cpu[k]));
    const double de = std::fabs(e_el - e_cpu) / std::fmax(1.0, std::fabs(e_cpu));
    std::printf("  form %-8s CPU energy %.12g, Element energy %.12g, max |grad diff| %.2e\n",
                smg::to_string(form), e_cpu, e_el, dg);
    bad += !(de < 1e-12 && dg < 1e-12 && e_cpu > 0);
  }
  return bad;
}
EOF
  local flags
  flags=$(sed -n 's/^CMAKE_CXX_FLAGS_RELEASE:STRING=//p' "$BUILD/CMakeCache.txt")
  g++ -std=c++17 $flags -Wall -Wextra -Werror -Iinclude $(pkg-config --cflags eigen3 2>/dev/null || echo -I/usr/include/eigen3) \
    "$TMP/element_check.cpp" -o "$TMP/element_check" -pthread && "$TMP/element_check"
}
check_docs() { python3 scripts/check_docs.py 2>"$TMP/check_docs.err"; }
cuda_host() {
  cmake -S . -B "$WT/build/dry-cuda" -G Ninja -DCMAKE_BUILD_TYPE=Release -DSMG_BUILD_TESTS=ON \
    -DSMG_BUILD_EXAMPLES=OFF -DSMG_BUILD_BENCH=OFF -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=ON \
    >"$TMP/cuda.log" 2>&1 &&
    cmake --build "$WT/build/dry-cuda" -j "$JOBS" --target test_cuda >>"$TMP/cuda.log" 2>&1 &&
    "$WT/build/dry-cuda/tests/cuda/test_cuda" -ts=cuda-host 2>&1 | tail -3
}

check "configure" configure
if [ "${SMG_DRY_RUN_BASELINE:-1}" = 1 ] && [ "${RESULTS[0]}" = PASS ]; then
  check "baseline: the same build and tests on HEAD, without the term" baseline
fi

# ---- New files (section 3, steps 1-3) ---------------------------------------------------------
# The next free equation label (step 3): one above the largest E label defined in docs/math.
LABEL=E$(( $(grep -rhoE '\(E[0-9]+\)' docs/math | tr -dc '0-9\n' | sort -n | tail -1) + 1 ))
export LABEL

cat > include/smg/energy/terms/dryrun.hpp <<'EOF'
// smg/energy/terms/dryrun.hpp — THROWAWAY (scripts/term_dry_run.sh writes and removes it): a
// trivial trajectory term of the regulariser driver (energy/block.hpp has the concept), (@LABEL@):
//   D = Σ_i Σ_{t=0}^{T−2} P(v_i^t),  v_i^t = x_i^{t+1} − x_i^t
//   P(v) = k ‖v‖² (form squared, the default) or k ‖v‖⁴ (form quartic), k = the weight.
// Each term is indexed by its earlier frame, which the block owns (reach 1).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>

#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/options.hpp"

namespace smg {

// The form of (@LABEL@): a named enum (enum_values), so the bindings spell it by name.
enum class DryrunForm { squared, quartic };
inline constexpr DryrunForm kDryrunForms[] = {DryrunForm::squared, DryrunForm::quartic};
constexpr const char* to_string(DryrunForm f) {
  return f == DryrunForm::quartic ? "quartic" : "squared";
}
constexpr const auto& enum_values(DryrunForm) { return kDryrunForms; }

struct DryrunOptions {
  DryrunForm form = DryrunForm::squared;
  double weight = 1.0;  // k
};

template <class O, class F, detail::IfOptions<O, DryrunOptions> = 0>
void for_each_option(O& o, F&& f) {
  f("form", o.form);
  f("weight", o.weight);
}

inline Status validate_options(const DryrunOptions& o) {
  return detail::first_error({detail::check_enum("DryrunOptions", "form", o.form),
                              detail::check_nonneg("DryrunOptions", "weight", o.weight)});
}

// Checks the arguments of dryrun(): positions [T][N][3]; the gradient may be empty.
template <class S>
Status validate_dryrun(detail::NonDeducedT<PositionsView<const S>> positions,
                       const DryrunOptions& options, PositionsView<S> grad_positions = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  return detail::first_error({validate_positions<S>(positions, -1, -1, "positions"),
                              validate_options(options),
                              validate_optional_output(grad_positions, T, N, "grad_positions")});
}

// P(v) of (@LABEL@) for the difference v (3 values) and factor k; writes g = ∂P/∂v:
//   squared  k ‖v‖²   g = 2 k v;   quartic  k ‖v‖⁴   g = 4 k ‖v‖² v.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S dryrun_penalty(bool quartic, S k, const S* v, S* g) {
  const S vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
  const S h = quartic ? S(L(4) * k * vv) : S(L(2) * k);
  for (int d = 0; d < 3; ++d) g[d] = h * v[d];
  return quartic ? S(k * vv * vv) : S(k * vv);
}

// (@LABEL@) as one element (frame t, node i) of the CUDA driver's element pass: the energy of the
// term whose earlier frame is t into `energy`, x_i^t's gradient from the terms t − 1 and t added
// to grad_x [T][N][3] when not null. Host values: DryrunTerm::element().
template <class S>
struct DryrunElement {
  Literal<S> k = Literal<S>(0);
  bool quartic = false;

  bool reads_confidence() const { return false; }

  SMG_HOST_DEVICE void at(Index t, Index i, PositionsView<const S> x, const S*, S* grad_x,
                          S& energy) const {
    const Index T = x.frames(), N = x.nodes();
    S g[3] = {S(0), S(0), S(0)};
    for (Index u = t - 1; u <= t; ++u) {
      if (u < 0 || u + 1 >= T) continue;
      const S* r0 = x.ptr(u, i);
      const S* r1 = x.ptr(u + 1, i);
      S v[3], gv[3];
      for (int d = 0; d < 3; ++d) v[d] = r1[d] - r0[d];
      const S e = dryrun_penalty<S, Literal<S>>(quartic, S(k), v, gv);
      if (u == t) energy += e;
      for (int d = 0; d < 3; ++d) g[d] += u == t ? S(-gv[d]) : gv[d];
    }
    if (grad_x != nullptr)
      for (int d = 0; d < 3; ++d) grad_x[(t * N + i) * 3 + d] += g[d];
  }
};

namespace detail {

template <class S, class I>
struct DryrunTerm : ScratchFreeTerm {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  bool enabled = false, quartic = false;
  double k_d = 0;
  Index T = 0;

  void configure(const DryrunOptions& o, Index frames, Index nodes) {
    T = frames;
    quartic = o.form == DryrunForm::quartic;
    k_d = o.weight;
    enabled = frames > 1 && nodes > 0 && o.weight != 0.0;
  }

  // The list's entry "dryrun".
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (o.terms.dryrun) configure(o.dryrun, s.T, s.N);
  }

  bool on() const { return enabled; }
  Index reach() const { return 1; }

  using Element = DryrunElement<S>;
  Element element() const {
    Element e;
    e.k = L(k_d);
    e.quartic = quartic;
    return e;
  }
  static Acc& energy_of(RegularizerResult<S>& r) { return r.dryrun; }

  template <class E>
  void node(const BlockView<S, I>& v, Block&, Index i, E& energy) const {
    const Index ne = v.ne, last = std::min(v.nown, T - 1 - v.t0);
    const S* X = v.Xb + i * v.n4();
    S* G = v.GBx ? v.GBx + i * v.n3() : nullptr;
    const S k = S(L(k_d));
    Acc e(0);
    for (Index l = 0; l < last; ++l) {
      S a[3], g[3];
      for (int d = 0; d < 3; ++d) a[d] = X[d * ne + l + 1] - X[d * ne + l];
      e += Acc(dryrun_penalty<S, L>(quartic, k, a, g));
      if (!G) continue;
      for (int d = 0; d < 3; ++d) {
        G[d * ne + l] -= g[d];
        G[d * ne + l + 1] += g[d];
      }
    }
    energy.dryrun += e;
  }
};

}  // namespace detail
}  // namespace smg
EOF

cat > include/smg/energy/dryrun.hpp <<'EOF'
// smg/energy/dryrun.hpp — THROWAWAY (scripts/term_dry_run.sh): the term (@LABEL@) as a separate
// operator, a one-term call of the driver (its argument check is in terms/dryrun.hpp).
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/dryrun.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// (@LABEL@), returned in Accumulator<S>; the gradient w.r.t. positions is *added* to grad_positions
// [T][N][3]. Precondition: validate_dryrun.
template <class S>
Accumulator<S> dryrun(detail::NonDeducedT<PositionsView<const S>> positions,
                      const DryrunOptions& options, PositionsView<S> grad_positions = {},
                      EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  SMG_ASSERT(detail::absent_or_shape(grad_positions, T, N), "dryrun: grad_positions shape");
  if (T == 0 || N == 0) return Accumulator<S>(0);
  using I = std::int32_t;
  detail::DryrunTerm<S, I> term;
  term.configure(options, T, N);
  if (!term.on()) return Accumulator<S>(0);
  return detail::drive_one_term<S, I>(positions, QuaternionsView<const S>(),
                                      FrameScalarsView<const S>(),
                                      NeighborsView<S, I>(nullptr, nullptr, N, 0), grad_positions,
                                      RotationGradientView<S>(), workspace, parallel, term)
      .dryrun;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg
EOF

cat > docs/math/terms/dryrun.md <<'EOF'
# (@LABEL@) Dry-run term (throwaway)

Written and removed by `scripts/term_dry_run.sh`; never committed. Term `dryrun` of the fused
step (`RegularizerTerms::dryrun`, `DryrunOptions`), header `energy/terms/dryrun.hpp`
(`DryrunTerm`, `DryrunElement`), separate operator `dryrun()` (`energy/dryrun.hpp`):

    D = Σ_i Σ_{t=0}^{T−2} P(x_i^{t+1} − x_i^t),   P(v) = k ‖v‖² (squared) or k ‖v‖⁴ (quartic)

with k = `weight`; ∂P/∂v = 2 k v or 4 k ‖v‖² v, and ∂v/∂x^{t+1} = I, ∂v/∂x^t = −I.
EOF

sed -i "s/@LABEL@/$LABEL/g" include/smg/energy/terms/dryrun.hpp include/smg/energy/dryrun.hpp \
  docs/math/terms/dryrun.md

# ---- Edits of existing files, by anchors (section 3, steps 4-6) -------------------------------

python3 - <<'PYEOF'
import os
import sys

LABEL = os.environ["LABEL"]

def edit(path, anchor, text, where="after", old=None):
    """Insert `text` after/before the line holding `anchor` (which must occur exactly once), or
    with where="replace" replace `anchor` by `text`."""
    with open(path, encoding="utf-8") as f:
        src = f.read()
    n = src.count(anchor)
    if n != 1:
        sys.exit("term_dry_run: anchor found %d times in %s: %r" % (n, path, anchor))
    if where == "replace":
        src = src.replace(anchor, text)
    else:
        at = src.index(anchor)
        if where == "after":
            at = src.index("\n", at) + 1
        else:
            at = src.rindex("\n", 0, at) + 1
        src = src[:at] + text + src[at:]
    with open(path, "w", encoding="utf-8") as f:
        f.write(src.replace("@LABEL@", LABEL))


L = "include/smg/energy/term_list.hpp"
edit(L, '#include "smg/energy/terms/confidence.hpp"', '#include "smg/energy/terms/dryrun.hpp"\n')
edit(L, "  X(relrot,", "  X(dryrun, DryrunOptions, DryrunTerm, false) /* (@LABEL@), throwaway */ \\\n", "before")

edit("include/smg/energy/regularizers.hpp", '#include "smg/energy/confidence.hpp"', '#include "smg/energy/dryrun.hpp"\n')

P = "tests/support/operators.hpp"
edit(P, "// A term's operator (Accel, Carap, Angle) with each other penalty", """\
// THROWAWAY (scripts/term_dry_run.sh): the dry-run term (@LABEL@), default options.
struct Dryrun : TermOperator<Dryrun> {
  static constexpr const char* name = "dryrun";
  static constexpr const char* term = "dryrun";
  static constexpr bool exact_gradient = true;
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S> gx,
                                 detail::NonDeducedT<RotationGradientView<S>>, FrameScalarsView<S>,
                                 EnergyWorkspace<S>* workspace, ParallelOptions parallel) {
    return dryrun(in.positions, o.dryrun, gx, workspace, parallel);
  }
  static constexpr unsigned reads = 0;
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_dryrun<S>(in.positions, o.dryrun, out.positions);
  }
};

""", "before")
edit(P, "Lrm, Accel, Angle, Relrot>{}", "Lrm, Accel, Angle, Relrot, Dryrun>{}", "replace")
PYEOF

# The docs' terms table is generated (scripts/terms_table.py), not edited by hand.
python3 scripts/terms_table.py --write docs/api.md >/dev/null
# Staged, as a contributor's commit would have them: check_docs.py reads the files git lists.
git add -A


if [ "${RESULTS[0]}" = PASS ]; then
  check "build smg_cli test_energy test_api (-j$JOBS)" build
  if [ "${RESULTS[-1]}" = PASS ]; then
    check "test_energy -tc='*every*,smg_cli regularizers*'" energy_tests
    check "test_api" api_tests
    check "smg_cli regularizers --help lists --dryrun-form, --dryrun-weight" cli_help
  fi
  check "Element on the host (g++) equals the CPU term" element_host
fi
check "check_docs.py (terms table, labels, term pieces)" check_docs
if [ "${SMG_DRY_RUN_CUDA:-0}" = 1 ]; then
  check "CUDA host suite (test_cuda -ts=cuda-host)" cuda_host
fi

# ---- Report ------------------------------------------------------------------------------------

git add -A  # anything a build or a check wrote outside the ignored build/ is counted too
mapfile -t CREATED < <(git diff --cached --name-only --diff-filter=A HEAD)
mapfile -t EDITED < <(git diff --cached --name-only --diff-filter=MD HEAD)
echo
echo "files created (${#CREATED[@]}):"
for f in "${CREATED[@]}"; do echo "  $f ($(wc -l <"$f") lines)"; done
echo "files edited (${#EDITED[@]}):"
for f in "${EDITED[@]}"; do echo "  $f ($(git diff --cached --numstat HEAD -- "$f" | awk '{print "+" $1 "/-" $2}'))"; done
echo "checks:"
fail=0
for k in "${!NAMES[@]}"; do
  echo "  ${RESULTS[$k]}  ${NAMES[$k]}"
  [ "${RESULTS[$k]}" = PASS ] || fail=1
done
echo "term_dry_run: $([ $fail = 0 ] && echo "all checks passed" || echo "FAILED") in $(( $(date +%s) - START )) s; removing the worktree"
exit $fail

// smg/core/validate.hpp — one validation function per view kind.
//
// Each returns Status::ok() or a one-line message naming the argument and the problem:
// wrong shape, null data, NaN/Inf (with the first offending index), zero quaternions (and,
// only with QuaternionNorm::require_unit, unnormalised ones: the default accepts any finite
// nonzero quaternion, which the entry points normalise), visibility values other than 0/1. Entry points call these once; hot loops never
// check. Pass -1 for an expected size that is not constrained.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <sstream>
#include <string>
#include <type_traits>

#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/views.hpp"

namespace smg {

// How validate_quaternions treats a non-unit norm.
enum class QuaternionNorm {
  normalize_on_entry,  // any finite nonzero quaternion is accepted (the entry point normalises)
  require_unit,        // |1 - |q|| must be <= unit_tolerance<Scalar>()
};

namespace detail {
inline std::string shape_string(Index a, Index b, Index c, const char* na, const char* nb) {
  std::ostringstream s;
  s << "[" << na << "=" << a << "][" << nb << "=" << b << "]";
  if (c >= 0) s << "[" << c << "]";
  return s.str();
}
inline std::string expected_string(Index a, Index b, Index c, const char* na, const char* nb) {
  std::ostringstream s;
  s << "[" << na << "=";
  if (a >= 0) s << a; else s << "any";
  s << "][" << nb << "=";
  if (b >= 0) s << b; else s << "any";
  s << "]";
  if (c >= 0) s << "[" << c << "]";
  return s.str();
}
// Shape + null check shared by every validator. dim < 0: no channel dimension (visibility).
inline Status check_shape(const std::string& name, const void* data, Index a, Index b, Index dim,
                          Index expect_a, Index expect_b, Index expect_dim, const char* na,
                          const char* nb) {
  const bool dim_ok = expect_dim < 0 || dim == expect_dim;
  if ((expect_a >= 0 && a != expect_a) || (expect_b >= 0 && b != expect_b) || !dim_ok ||
      a < 0 || b < 0) {
    return Status::error(name + ": expected shape " +
                         expected_string(expect_a, expect_b, expect_dim, na, nb) + ", got " +
                         shape_string(a, b, dim, na, nb));
  }
  if (data == nullptr && a * b * (dim < 0 ? 1 : dim) > 0) {
    return Status::error(name + ": null data pointer for a non-empty array");
  }
  return Status::ok();
}
template <class S>
inline const char* nonfinite_kind(const S& v) {
  return std::isnan(v) ? "NaN" : "Inf";
}
inline std::string at_string(Index t, Index i, const char* na, const char* nb) {
  std::ostringstream s;
  s << "[" << na << "=" << t << "][" << nb << "=" << i << "]";
  return s.str();
}
template <class T, int Dim>
inline Status check_finite(const std::string& name, const SequenceView<T, Dim>& v, const char* na,
                           const char* nb) {
  for (Index t = 0; t < v.frames(); ++t)
    for (Index i = 0; i < v.nodes(); ++i) {
      const auto* p = v.ptr(t, i);
      for (Index c = 0; c < v.dim(); ++c)
        if (!std::isfinite(p[c]))
          return Status::error(name + ": element " + at_string(t, i, na, nb) + " is " +
                               nonfinite_kind(p[c]));
    }
  return Status::ok();
}
}  // namespace detail

// positions [T][N][3]: shape, non-null, finite.
template <class S>
Status validate_positions(PositionsView<const S> x, Index frames, Index nodes,
                          const std::string& name = "positions") {
  if (Status s = detail::check_shape(name, x.data(), x.frames(), x.nodes(), 3, frames, nodes, 3,
                                     "T", "N");
      !s)
    return s;
  return detail::check_finite(name, x, "t", "i");
}

// quaternions [T][N][4] (w, x, y, z): shape, non-null, finite, nonzero; with
// QuaternionNorm::require_unit also |1 - |q|| <= unit_tolerance<S>().
template <class S>
Status validate_quaternions(QuaternionsView<const S> q, Index frames, Index nodes,
                            QuaternionNorm norm = QuaternionNorm::normalize_on_entry,
                            const std::string& name = "quaternions") {
  if (Status s = detail::check_shape(name, q.data(), q.frames(), q.nodes(), 4, frames, nodes, 4,
                                     "T", "N");
      !s)
    return s;
  if (Status s = detail::check_finite(name, q, "t", "i"); !s) return s;
  for (Index t = 0; t < q.frames(); ++t)
    for (Index i = 0; i < q.nodes(); ++i) {
      const S n = q(t, i).norm();
      if (!(n > S(0)))
        return Status::error(name + ": element " + detail::at_string(t, i, "t", "i") +
                             " is the zero quaternion");
      if (norm == QuaternionNorm::require_unit && std::abs(n - S(1)) > unit_tolerance<S>()) {
        std::ostringstream s;
        s << name << ": element " << detail::at_string(t, i, "t", "i")
          << " is not a unit quaternion (norm " << n << ")";
        return Status::error(s.str());
      }
    }
  return Status::ok();
}

// visibility [T][N]: shape, non-null, every value 0 or 1.
template <class V>
Status validate_visibility(VisibilityView<const V> v, Index frames, Index nodes,
                           const std::string& name = "visibility") {
  if (Status s = detail::check_shape(name, v.data(), v.frames(), v.nodes(), -1, frames, nodes, -1,
                                     "T", "N");
      !s)
    return s;
  for (Index t = 0; t < v.frames(); ++t)
    for (Index i = 0; i < v.nodes(); ++i)
      if (!(v(t, i) == V(0) || v(t, i) == V(1))) {
        std::ostringstream s;
        s << name << ": element " << detail::at_string(t, i, "t", "i") << " is "
          << +v(t, i) << ", expected 0 or 1";
        return Status::error(s.str());
      }
  return Status::ok();
}

// feature samples [T][N][C]: shape, non-null, finite. channels < 0: any C >= 1.
template <class S>
Status validate_feature_samples(FeatureSamplesView<const S> g, Index frames, Index nodes,
                                Index channels = -1,
                                const std::string& name = "feature_samples") {
  if (Status s = detail::check_shape(name, g.data(), g.frames(), g.nodes(), g.dim(), frames, nodes,
                                     channels, "T", "N");
      !s)
    return s;
  if (g.dim() < 1) return Status::error(name + ": needs at least one channel");
  return detail::check_finite(name, g, "t", "i");
}

// features [N][C]: shape, non-null, finite. channels < 0: any C >= 1.
template <class S>
Status validate_features(FeaturesView<const S> f, Index nodes, Index channels = -1,
                         const std::string& name = "features") {
  if (Status s = detail::check_shape(name, f.data(), f.rows(), f.cols(), -1, nodes, channels, -1,
                                     "N", "C");
      !s)
    return s;
  if (f.cols() < 1) return Status::error(name + ": needs at least one channel");
  for (Index i = 0; i < f.rows(); ++i)
    for (Index c = 0; c < f.cols(); ++c)
      if (!std::isfinite(f(i, c)))
        return Status::error(name + ": element " + detail::at_string(i, c, "i", "c") + " is " +
                             detail::nonfinite_kind(f(i, c)));
  return Status::ok();
}

// Mutable views: the validators above also take a view of non-const elements (the caller's
// writable buffer) without a template argument, e.g. validate_positions(PositionsView<double>).
// (The const overloads cannot deduce S from a mutable view; these forward to them.)
namespace detail {
template <class V, int Dim>
struct IsMutableSequenceView : std::false_type {};
template <class T, int Dim>
struct IsMutableSequenceView<SequenceView<T, Dim>, Dim> : std::bool_constant<!std::is_const_v<T>> {};
template <class V, int Cols>
struct IsMutableTableView : std::false_type {};
template <class T, int Cols>
struct IsMutableTableView<TableView<T, Cols>, Cols> : std::bool_constant<!std::is_const_v<T>> {};
template <class V, int Dim>
using EnableMutableSequence = std::enable_if_t<IsMutableSequenceView<V, Dim>::value, int>;
template <class V, int Cols>
using EnableMutableTable = std::enable_if_t<IsMutableTableView<V, Cols>::value, int>;
}  // namespace detail

template <class View, detail::EnableMutableSequence<View, 3> = 0>
Status validate_positions(const View& x, Index frames, Index nodes,
                          const std::string& name = "positions") {
  return validate_positions<typename View::Value>(x, frames, nodes, name);
}
template <class View, detail::EnableMutableSequence<View, 4> = 0>
Status validate_quaternions(const View& q, Index frames, Index nodes,
                            QuaternionNorm norm = QuaternionNorm::normalize_on_entry,
                            const std::string& name = "quaternions") {
  return validate_quaternions<typename View::Value>(q, frames, nodes, norm, name);
}
template <class View, detail::EnableMutableSequence<View, 1> = 0>
Status validate_visibility(const View& v, Index frames, Index nodes,
                           const std::string& name = "visibility") {
  return validate_visibility<typename View::Value>(v, frames, nodes, name);
}
template <class View, detail::EnableMutableSequence<View, Eigen::Dynamic> = 0>
Status validate_feature_samples(const View& g, Index frames, Index nodes, Index channels = -1,
                                const std::string& name = "feature_samples") {
  return validate_feature_samples<typename View::Value>(g, frames, nodes, channels, name);
}
template <class View, detail::EnableMutableTable<View, Eigen::Dynamic> = 0>
Status validate_features(const View& f, Index nodes, Index channels = -1,
                         const std::string& name = "features") {
  return validate_features<typename View::Value>(f, nodes, channels, name);
}

// An output buffer (gradient [T][N][Dim]): shape and non-null only; its contents are written.
template <class S, int Dim>
Status validate_output(SequenceView<S, Dim> out, Index frames, Index nodes,
                       const std::string& name) {
  return detail::check_shape(name, out.data(), out.frames(), out.nodes(),
                             Dim == 1 ? Index(-1) : out.dim(), frames, nodes,
                             Dim == 1 ? Index(-1) : Index(Dim), "T", "N");
}

// The same for an optional output: an empty view (null data) means "not computed" and passes.
template <class S, int Dim>
Status validate_optional_output(SequenceView<S, Dim> out, Index frames, Index nodes,
                                const std::string& name) {
  if (out.data() == nullptr) return Status::ok();
  return validate_output(out, frames, nodes, name);
}

}  // namespace smg

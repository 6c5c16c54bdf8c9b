// smg/core/views.hpp — non-owning views over caller memory.
//
// smg never owns big arrays. Inputs and outputs are (pointer, sizes) over contiguous,
// row-major memory laid out like a C-order NumPy array or a contiguous PyTorch tensor, so a
// torch extension, a CUDA host program or NumPy can call smg without copies:
//
//   positions      [T][N][3]   SequenceView<const S, 3>   (PositionsView)
//   quaternions    [T][N][4]   SequenceView<const S, 4>   (QuaternionsView), (w, x, y, z)
//   visibility     [T][N]      SequenceView<const std::uint8_t, 1>   (VisibilityView)
//   feature samples[T][N][C]   SequenceView<const S, Eigen::Dynamic>
//   features       [N][C]      TableView<const S, Eigen::Dynamic>    (FeaturesView)
//   gradients      same layout as their variable, non-const element type; the gradient of
//                  a rotation is a right-tangent 3-vector: TangentsView [T][N][3].
//
// A view with a const element type is an input; a non-const one may be written. A mutable
// view converts implicitly to its const counterpart. Views are cheap to copy (pass by value).
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <type_traits>

#include "smg/core/types.hpp"

namespace smg {

namespace detail {
template <class T, int Dim>
using VectorMap = std::conditional_t<std::is_const_v<T>,
                                     Eigen::Map<const Eigen::Matrix<std::remove_const_t<T>, Dim, 1>>,
                                     Eigen::Map<Eigen::Matrix<std::remove_const_t<T>, Dim, 1>>>;

// What every view over elements T names alike: its element type as given (const for an input)
// and its value type. A base of SequenceView and TableView, so that both spell them once (empty:
// no size or layout cost).
template <class T>
struct ViewElementTypes {
  using Element = T;
  using Value = std::remove_const_t<T>;
};

// The one conversion between views of the same layout: from elements U to T = const U (mutable
// to const). Enables the converting constructors of SequenceView and TableView.
template <class U, class T>
using EnableAddConst = std::enable_if_t<std::is_same_v<const U, T> && !std::is_same_v<U, T>>;
}  // namespace detail

// [frames][nodes][dim] array. Dim is a compile-time channel count (3 for positions, 4 for
// quaternions, 1 for per-frame scalars) or Eigen::Dynamic (feature samples: dim() = C).
template <class T, int Dim>
class SequenceView : public detail::ViewElementTypes<T> {
 public:
  SequenceView() = default;
  // Fixed channel count.
  SMG_HOST_DEVICE SequenceView(T* data, Index frames, Index nodes)
      : data_(data), frames_(frames), nodes_(nodes), dim_(Dim == Eigen::Dynamic ? 0 : Dim) {
    static_assert(Dim != Eigen::Dynamic, "pass the channel count for a dynamic view");
  }
  // Runtime channel count (Dim == Eigen::Dynamic).
  SMG_HOST_DEVICE SequenceView(T* data, Index frames, Index nodes, Index dim)
      : data_(data), frames_(frames), nodes_(nodes), dim_(dim) {
    static_assert(Dim == Eigen::Dynamic, "the channel count is fixed by the type");
  }
  // Mutable -> const.
  template <class U, class = detail::EnableAddConst<U, T>>
  SMG_HOST_DEVICE SequenceView(const SequenceView<U, Dim>& other)  // NOLINT(google-explicit-constructor)
      : data_(other.data()), frames_(other.frames()), nodes_(other.nodes()), dim_(other.dim()) {}

  SMG_HOST_DEVICE T* data() const { return data_; }
  SMG_HOST_DEVICE Index frames() const { return frames_; }
  SMG_HOST_DEVICE Index nodes() const { return nodes_; }
  SMG_HOST_DEVICE Index dim() const { return dim_; }
  SMG_HOST_DEVICE Index size() const { return frames_ * nodes_ * dim_; }
  SMG_HOST_DEVICE bool empty() const { return size() == 0; }

  // Element (t, i): a Map of the Dim-vector, or a reference when Dim == 1.
  SMG_HOST_DEVICE decltype(auto) operator()(Index t, Index i) const {
    SMG_ASSERT(t >= 0 && t < frames_ && i >= 0 && i < nodes_, "SequenceView index out of range");
    if constexpr (Dim == 1) {
      return (data_[t * nodes_ + i]);
    } else {
      return detail::VectorMap<T, Dim>(data_ + (t * nodes_ + i) * dim_, dim_);
    }
  }
  // Pointer to the first channel of element (t, i); (frames, 0) gives the end pointer.
  SMG_HOST_DEVICE T* ptr(Index t, Index i) const {
    SMG_ASSERT(t >= 0 && i >= 0 && i <= nodes_ && t * nodes_ + i <= frames_ * nodes_,
               "SequenceView::ptr out of range");
    return data_ + (t * nodes_ + i) * dim_;
  }

 private:
  T* data_ = nullptr;
  Index frames_ = 0;
  Index nodes_ = 0;
  Index dim_ = 0;
};

// [rows][cols] array. Cols is compile-time or Eigen::Dynamic (features [N][C], graph
// indices/weights [N][K]).
template <class T, int Cols>
class TableView : public detail::ViewElementTypes<T> {
 public:
  TableView() = default;
  SMG_HOST_DEVICE TableView(T* data, Index rows, Index cols) : data_(data), rows_(rows), cols_(cols) {}
  SMG_HOST_DEVICE TableView(T* data, Index rows) : data_(data), rows_(rows), cols_(Cols) {
    static_assert(Cols != Eigen::Dynamic, "pass the column count for a dynamic view");
  }
  template <class U, class = detail::EnableAddConst<U, T>>
  SMG_HOST_DEVICE TableView(const TableView<U, Cols>& other)  // NOLINT(google-explicit-constructor)
      : data_(other.data()), rows_(other.rows()), cols_(other.cols()) {}

  SMG_HOST_DEVICE T* data() const { return data_; }
  SMG_HOST_DEVICE Index rows() const { return rows_; }
  SMG_HOST_DEVICE Index cols() const { return cols_; }
  SMG_HOST_DEVICE Index size() const { return rows_ * cols_; }
  SMG_HOST_DEVICE bool empty() const { return size() == 0; }

  SMG_HOST_DEVICE T& operator()(Index r, Index c) const {
    SMG_ASSERT(r >= 0 && r < rows_ && c >= 0 && c < cols_, "TableView index out of range");
    return data_[r * cols_ + c];
  }
  // Row r as a Map of a column vector.
  SMG_HOST_DEVICE detail::VectorMap<T, Cols> row(Index r) const {
    SMG_ASSERT(r >= 0 && r < rows_, "TableView row out of range");
    return detail::VectorMap<T, Cols>(data_ + r * cols_, cols_);
  }
  // Pointer to row r; rows() gives the end pointer.
  SMG_HOST_DEVICE T* ptr(Index r) const {
    SMG_ASSERT(r >= 0 && r <= rows_, "TableView::ptr out of range");
    return data_ + r * cols_;
  }

 private:
  T* data_ = nullptr;
  Index rows_ = 0;
  Index cols_ = 0;
};

// Named layouts (docs/design.md "Conventions"). S may be const-qualified (input) or not (output).
template <class S> using PositionsView = SequenceView<S, 3>;    // [T][N][3], world units
template <class S> using QuaternionsView = SequenceView<S, 4>;  // [T][N][4], (w, x, y, z)
template <class S> using TangentsView = SequenceView<S, 3>;     // [T][N][3], right tangent
template <class V> using VisibilityView = SequenceView<V, 1>;   // [T][N], 0 or 1
template <class S> using FrameScalarsView = SequenceView<S, 1>; // [T][N] (confidences, ...)
template <class S> using FeatureSamplesView = SequenceView<S, Eigen::Dynamic>;  // [T][N][C]
template <class S> using FeaturesView = TableView<S, Eigen::Dynamic>;           // [N][C]

}  // namespace smg

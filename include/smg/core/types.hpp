// smg/core/types.hpp — fixed-size Eigen aliases used across smg.
//
// Every algorithm in smg is templated on its Scalar (float, double, or an Eigen
// AutoDiffScalar for cross-checks). Fixed-size types keep small maths on the stack.
#pragma once

#include "smg/core/config.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace smg {

using Index = Eigen::Index;

template <class S> using Vector2 = Eigen::Matrix<S, 2, 1>;
template <class S> using Vector3 = Eigen::Matrix<S, 3, 1>;
template <class S> using Vector4 = Eigen::Matrix<S, 4, 1>;
template <class S> using Vector8 = Eigen::Matrix<S, 8, 1>;
template <class S> using Matrix2 = Eigen::Matrix<S, 2, 2>;
template <class S> using Matrix3 = Eigen::Matrix<S, 3, 3>;
template <class S> using Matrix4 = Eigen::Matrix<S, 4, 4>;
template <class S> using Matrix43 = Eigen::Matrix<S, 4, 3>;
template <class S> using Matrix34 = Eigen::Matrix<S, 3, 4>;
template <class S> using Matrix38 = Eigen::Matrix<S, 3, 8>;
template <class S> using Matrix83 = Eigen::Matrix<S, 8, 3>;
template <class S> using Matrix8 = Eigen::Matrix<S, 8, 8>;
// Eigen stores quaternions as (x, y, z, w); smg's memory convention is (w, x, y, z).
// Convert only at the boundary (quaternion.hpp: from_wxyz / to_wxyz).
template <class S> using Quaternion = Eigen::Quaternion<S>;

namespace detail {
// A parameter type that does not take part in template argument deduction: the argument then
// converts to it (a TangentsView to a RotationGradientView<S>, nullptr to an output pointer)
// with S deduced from the other parameters.
template <class T>
struct NonDeduced {
  using type = T;
};
template <class T>
using NonDeducedT = typename NonDeduced<T>::type;
}  // namespace detail

}  // namespace smg

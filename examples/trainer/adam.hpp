// examples/trainer/adam.hpp — Adam (Kingma & Ba 2015) over flat parameter arrays, with a
// variant for unit quaternions that steps in the right tangent.
//
// A group holds one kind of parameter (means, log-scales, node positions, ...) as `rows` rows
// of `width` values, its first and second moments, and a learning rate. step() turns a
// gradient into the Adam step s = lr * m_hat / (sqrt(v_hat) + eps) and applies it:
//   vector parameters     x <- x - s
//   rotations (tangent)   q <- q ⊗ Exp(-s), renormalised, where the gradient is the
//                         right-tangent 3-vector of the library's convention (R <- R Exp(phi))
// Moments of a rotation live in its tangent space at the current iterate (the usual
// approximation of Riemannian Adam without transport; fine for the small steps used here).
// compact() drops rows (density control) together with their moments.
//
// The steps run on smg's deterministic parallel loop: every value's update reads and writes
// only its own moments (rows, for rotations), so the result is the same for any thread count.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "smg/core/parallel.hpp"
#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"

namespace trainer {

template <class S>
class Adam {
 public:
  Adam() = default;
  Adam(std::size_t values, double lr, double beta1 = 0.9, double beta2 = 0.999, double eps = 1e-15)
      : lr_(lr), beta1_(beta1), beta2_(beta2), eps_(eps), m_(values, S(0)), v_(values, S(0)) {}

  double lr() const { return lr_; }
  void set_lr(double lr) { lr_ = lr; }
  long long steps() const { return t_; }
  std::size_t size() const { return m_.size(); }

  // x <- x - Adam step, for n = size() values.
  void step(S* x, const S* grad, smg::ParallelOptions parallel = {}) {
    advance();
    const auto n = static_cast<smg::Index>(m_.size());
    smg::parallel_for(
        n,
        [&](smg::Index begin, smg::Index end) {
          for (auto k = static_cast<std::size_t>(begin); k < static_cast<std::size_t>(end); ++k)
            x[k] -= direction(k, grad[k]);
        },
        parallel);
  }

  // Unit quaternions [n][4] (w, x, y, z) with right-tangent gradients [n][3]; size() = 3n.
  void step_rotations(S* q, const S* grad_tangent, smg::ParallelOptions parallel = {}) {
    advance();
    const auto n = static_cast<smg::Index>(m_.size() / 3);
    smg::parallel_for(
        n,
        [&](smg::Index begin, smg::Index end) {
          for (auto r = static_cast<std::size_t>(begin); r < static_cast<std::size_t>(end); ++r) {
            Eigen::Matrix<S, 3, 1> s;
            for (int c = 0; c < 3; ++c) s(c) = direction(3 * r + c, grad_tangent[3 * r + c]);
            const Eigen::Quaternion<S> cur = smg::from_wxyz(q + 4 * r);
            const Eigen::Matrix<S, 3, 1> minus = -s;
            Eigen::Quaternion<S> next = cur * smg::so3::exp(minus);
            next.normalize();
            smg::to_wxyz(next, q + 4 * r);
          }
        },
        parallel);
  }

  // Keeps the rows (of `width` values) whose keep[row] is nonzero, in order.
  void compact(const std::vector<std::uint8_t>& keep, std::size_t width) {
    std::size_t w = 0;
    for (std::size_t r = 0; r < keep.size(); ++r) {
      if (!keep[r]) continue;
      for (std::size_t c = 0; c < width; ++c) {
        m_[w * width + c] = m_[r * width + c];
        v_[w * width + c] = v_[r * width + c];
      }
      ++w;
    }
    m_.resize(w * width);
    v_.resize(w * width);
  }

  // Appends rows with zero moments (new Gaussians).
  void grow(std::size_t values) {
    m_.resize(m_.size() + values, S(0));
    v_.resize(v_.size() + values, S(0));
  }

 private:
  void advance() {
    ++t_;
    c1_ = 1.0 - std::pow(beta1_, static_cast<double>(t_));
    c2_ = 1.0 - std::pow(beta2_, static_cast<double>(t_));
  }
  S direction(std::size_t k, S g) {
    m_[k] = static_cast<S>(beta1_) * m_[k] + static_cast<S>(1 - beta1_) * g;
    v_[k] = static_cast<S>(beta2_) * v_[k] + static_cast<S>(1 - beta2_) * g * g;
    const double mh = static_cast<double>(m_[k]) / c1_, vh = static_cast<double>(v_[k]) / c2_;
    return static_cast<S>(lr_ * mh / (std::sqrt(vh) + eps_));
  }

  double lr_ = 1e-3, beta1_ = 0.9, beta2_ = 0.999, eps_ = 1e-15;
  double c1_ = 1, c2_ = 1;
  long long t_ = 0;
  std::vector<S> m_, v_;
};

// Exponential decay from lr0 at progress 0 to lr1 at progress 1 (3DGS's position schedule).
inline double log_lerp(double lr0, double lr1, double progress) {
  if (progress <= 0) return lr0;
  if (progress >= 1) return lr1;
  return std::exp((1 - progress) * std::log(lr0) + progress * std::log(lr1));
}

}  // namespace trainer

// Tests of smg/core/views.hpp and smg/core/validate.hpp: indexing over caller memory and the
// validation messages for every view kind.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"

using smg::Index;

TEST_CASE("SequenceView indexes [T][N][D] row-major like a C-order array") {
  std::vector<double> buf(2 * 3 * 3);
  for (std::size_t k = 0; k < buf.size(); ++k) buf[k] = static_cast<double>(k);
  smg::PositionsView<double> x(buf.data(), 2, 3);
  CHECK(x.frames() == 2);
  CHECK(x.nodes() == 3);
  CHECK(x.size() == 18);
  CHECK(x(1, 2)(0) == 15.0);  // (1*3 + 2)*3
  x(1, 2)(1) = -1.0;          // writes through to caller memory
  CHECK(buf[16] == -1.0);
  smg::PositionsView<const double> cx = x;  // mutable -> const
  CHECK(cx(1, 2)(1) == -1.0);
  CHECK(cx.ptr(0, 1) == buf.data() + 3);

  std::vector<std::uint8_t> vis = {1, 0, 1, 1, 0, 0};
  smg::VisibilityView<const std::uint8_t> v(vis.data(), 2, 3);
  CHECK(v(0, 1) == 0);
  CHECK(v(1, 0) == 1);

  std::vector<float> g(2 * 3 * 5, 0.f);
  smg::FeatureSamplesView<float> gs(g.data(), 2, 3, 5);
  gs(1, 1)(4) = 7.f;
  CHECK(g[(1 * 3 + 1) * 5 + 4] == 7.f);
  CHECK(gs(1, 1).size() == 5);

  std::vector<int> idx = {0, 1, -1, 2, 0, -1};
  smg::TableView<const int, Eigen::Dynamic> t(idx.data(), 2, 3);
  CHECK(t(1, 0) == 2);
  CHECK(t.row(1)(2) == -1);
}

TEST_CASE("validate_positions: shape, null data, NaN and Inf are reported clearly") {
  std::vector<double> buf(2 * 3 * 3, 0.0);
  smg::PositionsView<const double> x(buf.data(), 2, 3);
  CHECK(smg::validate_positions(x, 2, 3).is_ok());
  CHECK(smg::validate_positions(x, -1, -1).is_ok());

  smg::Status s = smg::validate_positions(x, 3, 3);
  CHECK_FALSE(s);
  CHECK(s.message() == "positions: expected shape [T=3][N=3][3], got [T=2][N=3][3]");

  s = smg::validate_positions(smg::PositionsView<const double>(nullptr, 2, 3), 2, 3);
  CHECK(s.message() == "positions: null data pointer for a non-empty array");

  buf[(1 * 3 + 2) * 3 + 1] = std::numeric_limits<double>::quiet_NaN();
  s = smg::validate_positions(x, 2, 3, "x");
  CHECK(s.message() == "x: element [t=1][i=2] is NaN");
  buf[(1 * 3 + 2) * 3 + 1] = 0.0;
  buf[3] = -std::numeric_limits<double>::infinity();
  s = smg::validate_positions(x, 2, 3);
  CHECK(s.message() == "positions: element [t=0][i=1] is Inf");
}

TEST_CASE("validate_quaternions: zero, non-finite and unnormalised quaternions") {
  std::vector<float> q = {1, 0, 0, 0, 0.5f, 0.5f, 0.5f, 0.5f};
  smg::QuaternionsView<const float> qv(q.data(), 1, 2);
  CHECK(smg::validate_quaternions(qv, 1, 2).is_ok());
  CHECK(smg::validate_quaternions(qv, 1, 2, smg::QuaternionNorm::require_unit).is_ok());

  q[4] = 2.f;  // norm 2.18: accepted when normalised on entry, rejected when unit is required
  CHECK(smg::validate_quaternions(qv, 1, 2).is_ok());
  smg::Status s = smg::validate_quaternions(qv, 1, 2, smg::QuaternionNorm::require_unit, "quats");
  CHECK_FALSE(s);
  CHECK(s.message().rfind("quats: element [t=0][i=1] is not a unit quaternion (norm 2.17945)", 0) == 0);

  q[4] = q[5] = q[6] = q[7] = 0.f;
  s = smg::validate_quaternions(qv, 1, 2);
  CHECK(s.message() == "quaternions: element [t=0][i=1] is the zero quaternion");

  q[0] = std::numeric_limits<float>::infinity();
  s = smg::validate_quaternions(qv, 1, 2);
  CHECK(s.message() == "quaternions: element [t=0][i=0] is Inf");

  s = smg::validate_quaternions(qv, 1, 3);
  CHECK(s.message() == "quaternions: expected shape [T=1][N=3][4], got [T=1][N=2][4]");
}

TEST_CASE("validate_visibility, validate_features, validate_feature_samples, validate_output") {
  std::vector<std::uint8_t> vis = {1, 0, 2, 1};
  smg::VisibilityView<const std::uint8_t> v(vis.data(), 2, 2);
  smg::Status s = smg::validate_visibility(v, 2, 2);
  CHECK(s.message() == "visibility: element [t=1][i=0] is 2, expected 0 or 1");
  vis[2] = 0;
  CHECK(smg::validate_visibility(v, 2, 2).is_ok());
  CHECK(smg::validate_visibility(v, 2, 3).message() ==
        "visibility: expected shape [T=2][N=3], got [T=2][N=2]");

  std::vector<double> f = {1, 0, 0, 1, std::nan(""), 0};
  smg::FeaturesView<const double> fv(f.data(), 3, 2);
  CHECK(smg::validate_features(fv, 3).message() == "features: element [i=2][c=0] is NaN");
  CHECK(smg::validate_features(fv, 4, 2).message() ==
        "features: expected shape [N=4][C=2], got [N=3][C=2]");
  f[4] = 0.5;
  CHECK(smg::validate_features(fv, 3, 2).is_ok());

  std::vector<double> g(2 * 3 * 4, 0.1);
  smg::FeatureSamplesView<const double> gv(g.data(), 2, 3, 4);
  CHECK(smg::validate_feature_samples(gv, 2, 3).is_ok());
  CHECK(smg::validate_feature_samples(gv, 2, 3, 5).message() ==
        "feature_samples: expected shape [T=2][N=3][5], got [T=2][N=3][4]");
  g[23] = std::numeric_limits<double>::infinity();
  CHECK(smg::validate_feature_samples(gv, 2, 3).message() ==
        "feature_samples: element [t=1][i=2] is Inf");

  std::vector<double> out(2 * 3 * 3);
  CHECK(smg::validate_output(smg::TangentsView<double>(out.data(), 2, 3), 2, 3, "grad").is_ok());
  CHECK(smg::validate_output(smg::TangentsView<double>(out.data(), 2, 2), 2, 3, "grad").message() ==
        "grad: expected shape [T=2][N=3][3], got [T=2][N=2][3]");
  CHECK(smg::validate_output(smg::TangentsView<double>(nullptr, 2, 3), 2, 3, "grad").message() ==
        "grad: null data pointer for a non-empty array");
  // Empty arrays are valid with a null pointer.
  CHECK(smg::validate_positions(smg::PositionsView<const double>(nullptr, 0, 0), 0, 0).is_ok());
}

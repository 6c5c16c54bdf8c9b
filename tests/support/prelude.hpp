// tests/support/prelude.hpp — what the core, skin and energy tests share at the top of each file:
// seeded random inputs (support/random.hpp), finite differences (support/finite_diff.hpp), and
// the smg and Eigen names they use unqualified. Test files only (it declares names at global
// scope).
#pragma once

#include <Eigen/Core>

#include "smg/core/types.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"

using smg::Index;
using smg::Matrix3;
using smg::Quaternion;
using smg::Vector3;
using smg::Vector8;
using smg::test::central_jacobian;
using smg::test::relative_error;
using smg::test::Rng;
using Eigen::MatrixXd;
using Eigen::VectorXd;

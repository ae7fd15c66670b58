// Small pieces every Ceres fit in fit/ shares (private to the module: Ceres stays out of the
// public headers).
#pragma once

#include <Eigen/Core>
#include <ceres/ceres.h>

namespace insitu::fit {

// Levenberg-Marquardt with dense QR, silent, run to tight tolerances: the field fits have a
// handful of parameters and a few hundred residuals, and their answers are quoted to
// micrometres.
inline ceres::Solver::Options PreciseLmOptions(int max_iterations) {
  ceres::Solver::Options so;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.function_tolerance = 1e-14;
  so.parameter_tolerance = 1e-14;
  so.gradient_tolerance = 1e-16;
  so.logging_type = ceres::SILENT;
  return so;
}

// A Jacobian Ceres returned in compressed rows, as a dense matrix.
inline Eigen::MatrixXd DenseJacobian(const ceres::CRSMatrix& crs) {
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) j(r, crs.cols[k]) = crs.values[k];
  }
  return j;
}

}  // namespace insitu::fit

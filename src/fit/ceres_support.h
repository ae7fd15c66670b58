// Small pieces every Ceres fit in fit/ shares (private to the module: Ceres stays out of the
// public headers).
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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

// The Bayesian information criterion of a least-squares fit: m residual components, p
// parameters, residual sum of squares rss.
inline double Bic(double rss, int m, int p) {
  return m * std::log(std::max(rss, 1e-300) / m) + p * std::log(static_cast<double>(m));
}

// A Jacobian Ceres returned in compressed rows, as a dense matrix.
inline Eigen::MatrixXd DenseJacobian(const ceres::CRSMatrix& crs) {
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) j(r, crs.cols[k]) = crs.values[k];
  }
  return j;
}

// Standard errors in z from (J^T J)^-1 sigma^2. Columns are normalised first so that the test
// for a singular direction looks at correlation only; a parameter with a component in the null
// space (or a zero column) is not defined by the data: NaN.
inline std::vector<double> StandardErrorsZ(const Eigen::MatrixXd& jac, double sigma2) {
  const int p = static_cast<int>(jac.cols());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> se(p, nan);
  Eigen::VectorXd norm = jac.colwise().norm().transpose();
  std::vector<int> live;
  for (int j = 0; j < p; ++j) {
    if (norm(j) > 0.0 && std::isfinite(norm(j))) live.push_back(j);
  }
  if (live.empty()) return se;
  Eigen::MatrixXd a(jac.rows(), live.size());
  for (size_t c = 0; c < live.size(); ++c) a.col(c) = jac.col(live[c]) / norm(live[c]);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(a.transpose() * a);
  const Eigen::VectorXd& lambda = eig.eigenvalues();
  const Eigen::MatrixXd& v = eig.eigenvectors();
  // Normalised columns: eigenvalues sum to the column count; 1e-12 is far below any real
  // correlation and far above the finite-difference noise of the Jacobian (~1e-9 squared).
  const double floor = 1e-12 * lambda.maxCoeff();
  for (size_t c = 0; c < live.size(); ++c) {
    double var = 0.0, null = 0.0;
    for (int e = 0; e < lambda.size(); ++e) {
      if (lambda(e) > floor) {
        var += v(c, e) * v(c, e) / lambda(e);
      } else {
        null += v(c, e) * v(c, e);
      }
    }
    if (null < 1e-6) se[live[c]] = std::sqrt(var * sigma2) / norm(live[c]);
  }
  return se;
}

}  // namespace insitu::fit

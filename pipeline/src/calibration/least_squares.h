// Small dense nonlinear least squares for the metrology fits (hand-eye,
// projector pose correction): Eigen's Levenberg-Marquardt (unsupported
// module) with a forward-difference Jacobian, and the linearised covariance
// at the solution. Private to sl_pipeline.
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <unsupported/Eigen/LevenbergMarquardt>
#include <unsupported/Eigen/NumericalDiff>

namespace sl::pipeline::detail {

// r(x): the residual vector (its length fixed by `values`).
using ResidualFunction = std::function<void(const Eigen::VectorXd& x, Eigen::VectorXd& r)>;

struct LeastSquaresSolution {
  Eigen::VectorXd x;
  Eigen::VectorXd residuals;
  Eigen::MatrixXd jacobian;  // at x (central differences)
  int iterations = 0;
};

inline Eigen::MatrixXd numericJacobian(const ResidualFunction& f, const Eigen::VectorXd& x,
                                       int values, double step) {
  Eigen::MatrixXd J(values, x.size());
  Eigen::VectorXd xp = x, rp(values), rm(values);
  for (int j = 0; j < x.size(); ++j) {
    xp(j) = x(j) + step;
    f(xp, rp);
    xp(j) = x(j) - step;
    f(xp, rm);
    xp(j) = x(j);
    J.col(j) = (rp - rm) / (2 * step);
  }
  return J;
}

// Minimises |r(x)|^2 from x0. `step`: the finite-difference step of the
// parameters (they should be scaled alike: radians and millimetres here).
inline LeastSquaresSolution solveLeastSquares(const ResidualFunction& f, Eigen::VectorXd x0,
                                              int values, double step = 1e-6) {
  struct Functor : Eigen::DenseFunctor<double> {
    const ResidualFunction* f;
    Functor(const ResidualFunction* f, int inputs, int values)
        : Eigen::DenseFunctor<double>(inputs, values), f(f) {}
    int operator()(const InputType& x, ValueType& r) const {
      (*f)(x, r);
      return 0;
    }
  };
  if (values < x0.size())
    throw std::invalid_argument("least squares: " + std::to_string(values) +
                                " residuals for " + std::to_string(x0.size()) + " parameters");
  Functor functor(&f, static_cast<int>(x0.size()), values);
  Eigen::NumericalDiff<Functor, Eigen::Central> diff(functor, step * step);  // Eigen: h = sqrt(epsfcn) |x|
  Eigen::LevenbergMarquardt<Eigen::NumericalDiff<Functor, Eigen::Central>> lm(diff);
  lm.setMaxfev(200 * static_cast<int>(x0.size() + 1));
  lm.setXtol(1e-12);
  lm.setFtol(1e-12);
  lm.minimize(x0);
  LeastSquaresSolution s;
  s.x = x0;
  s.residuals.resize(values);
  f(s.x, s.residuals);
  s.jacobian = numericJacobian(f, s.x, values, step);
  s.iterations = static_cast<int>(lm.iterations());
  return s;
}

// Covariance of x: s^2 (J^T J)^-1, s^2 the residual variance with the
// degrees of freedom the fit used.
inline Eigen::MatrixXd covarianceOf(const LeastSquaresSolution& s) {
  const Eigen::Index m = s.residuals.size(), p = s.x.size();
  const double variance = s.residuals.squaredNorm() / double(std::max<Eigen::Index>(m - p, 1));
  const Eigen::MatrixXd JtJ = s.jacobian.transpose() * s.jacobian;
  return variance * JtJ.ldlt().solve(Eigen::MatrixXd::Identity(p, p));
}

// x = (rotation vector (rad), translation) -> the small pose exp(x).
inline Eigen::Isometry3d poseDelta(const Eigen::Ref<const Eigen::VectorXd>& x) {
  Eigen::Isometry3d d = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d w = x.head<3>();
  const double angle = w.norm();
  if (angle > 0) d.linear() = Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
  d.translation() = x.segment<3>(3);
  return d;
}

}  // namespace sl::pipeline::detail

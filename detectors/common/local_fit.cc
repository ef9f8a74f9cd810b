#include "detectors/common/local_fit.h"

#include <Eigen/Cholesky>

namespace linecal {

std::optional<Eigen::Vector2d> PredictQuadraticAtOrigin(std::span<const Eigen::Vector2d> offsets,
                                                        std::span<const Eigen::Vector2d> uv,
                                                        bool quad_x, bool quad_y) {
  if (offsets.size() != uv.size()) return std::nullopt;
  Eigen::Matrix<double, 6, 6> AtA = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 2> Atb = Eigen::Matrix<double, 6, 2>::Zero();
  for (std::size_t k = 0; k < offsets.size(); ++k) {
    const Eigen::Vector2d& d = offsets[k];
    Eigen::Matrix<double, 6, 1> b;
    b << 1.0, d.x(), d.y(), d.x() * d.y(), quad_x ? d.x() * d.x() : 0.0,
        quad_y ? d.y() * d.y() : 0.0;
    AtA += b * b.transpose();
    Atb += b * uv[k].transpose();
  }
  // Unused terms have zero rows: pin them so the system stays regular.
  for (int k = 4; k < 6; ++k) {
    if (AtA(k, k) == 0.0) AtA(k, k) = 1.0;
  }
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(AtA);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return std::nullopt;
  const Eigen::Matrix<double, 6, 2> coef = ldlt.solve(Atb);
  if (!coef.allFinite()) return std::nullopt;
  return Eigen::Vector2d(coef(0, 0), coef(0, 1));
}

}  // namespace linecal

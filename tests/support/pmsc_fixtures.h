// A PMSC model small enough to work by hand, shared by the pmsc and misslog tests.
#pragma once

#include <cstdlib>
#include <memory>
#include <random>
#include <vector>

#include <Eigen/QR>

#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/subspace.h"

namespace animspace::testing {

// Three points, one channel, a one-vector subspace a = (1, 2, 2)/3, zero mean, keys `keys`
// (key values (1, 1) at keys {0, 1} give f̂ = (0.6, 1.2, 1.2) and e_key = √0.1). Not prepared.
// Keys outside the model are kept (with a zero key row) so that tests can check their refusal.
inline pmsc::PmscModel three_point_model(const std::vector<int>& keys, pmsc::SoftCacheThresholds epsilon) {
  pmsc::PmscModel m;
  m.channel_count = 1;
  m.point_count = 3;
  m.control_point_count = 3;
  m.mean = Eigen::VectorXf::Zero(3);
  m.basis.resize(3, 1);
  m.basis << 1.0f / 3, 2.0f / 3, 2.0f / 3;
  m.key_points = keys;
  m.key_mean = Eigen::VectorXd::Zero(static_cast<long>(keys.size()));
  m.key_basis.resize(static_cast<long>(keys.size()), 1);
  for (size_t k = 0; k < keys.size(); ++k) {
    m.key_basis(static_cast<long>(k), 0) = keys[k] >= 0 && keys[k] < 3 ? m.basis(keys[k], 0) : 0.0f;
  }
  m.epsilon = epsilon;
  return m;
}

// A random prepared model: N points × 3 channels, M orthonormal basis vectors (as PCA gives), K
// keys spread over the points, a mean around 10 in each channel, ε = [0.05, 0.1].
inline pmsc::PmscModel random_model(std::mt19937& random, int points, int basis_size, int keys, bool aligned) {
  std::normal_distribution<float> normal;
  pmsc::PmscModel m;
  m.channel_count = 3;
  m.point_count = points;
  m.control_point_count = points;
  m.aligned = aligned;
  m.mean = Eigen::VectorXf::NullaryExpr(3 * points, [&] { return 10.0f + normal(random); });
  Eigen::MatrixXd a =
      Eigen::MatrixXd::NullaryExpr(3 * points, basis_size, [&] { return static_cast<double>(normal(random)); });
  a = a.householderQr().householderQ() * Eigen::MatrixXd::Identity(3 * points, basis_size);
  m.basis = a.cast<float>();
  for (int k = 0; k < keys; ++k) m.key_points.push_back(k * (points / keys));
  m.key_mean.resize(3 * keys);
  m.key_basis.resize(3 * keys, basis_size);
  for (int k = 0; k < keys; ++k) {
    const long point = m.key_points[static_cast<size_t>(k)];
    m.key_mean.segment(3 * k, 3) = m.mean.segment(3 * point, 3).cast<double>();
    m.key_basis.middleRows(3 * k, 3) = m.basis.middleRows(3 * point, 3).cast<double>();
  }
  m.epsilon = {0.05, 0.1};
  if (!pmsc::prepare_projection(m).ok()) m.projection.resize(0, 0);  // callers check projection's size
  return m;
}

// The runtime a server builds for `m` (a copy, prepared), for tests that drive the server's
// pipeline pieces directly.
inline std::shared_ptr<const pmsc::Subspace> runtime(const pmsc::PmscModel& m) {
  auto subspace = pmsc::make_subspace(std::make_shared<const pmsc::PmscModel>(m));
  if (!subspace.ok()) std::abort();  // a fixture's model is always servable
  return *subspace;
}

// Key values of a random pose near random_model's subspace, with noise of a random size so that
// verdicts vary across hit, blend and miss.
inline Eigen::VectorXf random_keys(std::mt19937& random, const pmsc::PmscModel& m) {
  std::normal_distribution<float> normal;
  const Eigen::VectorXf p = Eigen::VectorXf::NullaryExpr(m.basis_size(), [&] { return 3 * normal(random); });
  const Eigen::VectorXf frame = m.mean + m.basis * p;
  Eigen::VectorXf keys = pmsc::gather_key_values(m, frame);
  const float noise = std::uniform_real_distribution<float>(0, 0.15f)(random);
  for (long i = 0; i < keys.size(); ++i) keys(i) += noise * normal(random);
  return keys;
}

// How far apart two reconstructions of the same pose may be (batched and alone, or two batches),
// value by value: pmsc::reconstruction_rounding_bound times |mean_i| + Σ_j |A_ij p_j|, the size
// of the sum both round, computed here in double from the pose's coordinates.
inline Eigen::VectorXd reconstruction_tolerance(const pmsc::PmscModel& m, const Eigen::VectorXd& coordinates) {
  const Eigen::VectorXd p = coordinates.cast<float>().cast<double>().cwiseAbs();  // as reconstruct uses them
  return pmsc::reconstruction_rounding_bound(m.basis_size()) *
         (m.mean.cast<double>().cwiseAbs() + m.basis.cast<double>().cwiseAbs() * p);
}

}  // namespace animspace::testing

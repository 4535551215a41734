// A PMSC model small enough to work by hand, shared by the pmsc and misslog tests.
#pragma once

#include <vector>

#include "core/pmsc/pmsc_model.h"

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

}  // namespace animspace::testing

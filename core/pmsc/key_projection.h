// Eq. 2 with the key projection left to the kind (subspace.h): what a kind's runtime passes to
// estimate_coordinates when it solves p from the key values its own way, faster than the dense
// P = (A_keyᵀ A_key + λI)⁻¹ A_keyᵀ every kind has (pmsc_model.h). Internal to core/pmsc.
#pragma once

#include <functional>

#include <Eigen/Core>

#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

// Given the centred key values f_key − key_mean (K·D), sets p (M) and returns the key residual
// f_key − f̂_key. Only for models that are not aligned.
using KeyProjection = std::function<Eigen::VectorXd(Eigen::VectorXd centred, Eigen::VectorXd& p)>;

// estimate_coordinates (pmsc_model.h) with `projection` in place of the dense projection: every
// error the verdict reads is then made of its residual and p exactly as of the dense one's.
void estimate_coordinates_with(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                               const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out,
                               const KeyProjection& projection);

}  // namespace animspace::pmsc

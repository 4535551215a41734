// Localised secondary motion (issue #52): what a skinned character does that no skeleton pose
// explains — a hem flicks, a belly jiggles — added on top of posed frames, at a random place and of
// a random size in each frame, so that whether a soft cache sees it depends only on whether a key
// or check point happens to lie under it. Development data where the blind spot exists by
// construction: a rig poses exactly for any joint rotations, and these bumps are what its key
// points cannot have been chosen for.
#pragma once

#include <cstdint>

#include "core/common/types.h"

namespace animspace::animation_space {

// The bumps, as fractions of the rest pose's bounding-box diagonal.
struct SecondaryMotionOptions {
  double bumped_fraction = 0.5;       // of the frames that get a bump
  double max_amplitude_diag = 0.03;   // displacement at the bump's centre: uniform in [0, this]
  double min_radius_diag = 0.02;      // Gaussian falloff σ: uniform in [min, max]
  double max_radius_diag = 0.06;
};

// Adds to each bumped frame of `frames` (F × 3N, point-major, posed) one bump: a centre vertex c
// drawn uniformly, an amplitude a and a radius σ drawn from `options`, a uniformly random
// direction u, and every vertex i moved by a·u·exp(−‖p̂_i − p̂_c‖² / (2σ²)), distances measured
// on the rest pose `rest` (N × 3) so that the bump is a patch of skin in any pose. Deterministic
// for a seed. Returns the number of frames bumped.
int add_secondary_motion(const PointMatrix& rest, const SecondaryMotionOptions& options, uint64_t seed,
                         FrameMatrix& frames);

}  // namespace animspace::animation_space

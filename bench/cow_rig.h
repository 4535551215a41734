// The cow rig of the shared data (cow-rig/cow.{obj,tgf,DMAT}): a linear blend rig that poses
// exactly for any joint rotations, so the suites draw unlimited held-out poses from it.
#pragma once

#include <cstdio>
#include <filesystem>
#include <optional>

#include "core/animspace/import.h"

namespace animspace::bench {

// The rig under `data`/cow-rig, or nullopt after printing why the suite skips it.
inline std::optional<animation_space::ImportedRig> read_cow_rig(const std::filesystem::path& data) {
  const std::filesystem::path dir = data / "cow-rig";
  auto rig = animation_space::read_libigl_rig(dir / "cow.obj", dir / "cow.tgf", dir / "cow.DMAT");
  if (!rig) {
    std::printf("cow-rig: %s (skipped)\n", rig.error().message.c_str());
    return std::nullopt;
  }
  return std::move(*rig);
}

}  // namespace animspace::bench

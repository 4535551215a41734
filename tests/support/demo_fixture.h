// The demo models the integration suites start from, made once per ctest run.
//
// ctest runs every test in its own process (gtest_discover_tests), so a suite set-up that writes
// the demo writes it once per test: under AddressSanitizer about 7 s for the arm's models and
// 100 s for arm-smooth's atlas or the Cornell box's gathers, more than a hundred times a run. The
// ctest fixture `integration_demo` (tests/CMakeLists.txt) writes the bundled demo once with
// `animspace demo-repository` — the same demo:: functions, default options — into the folder
// ANIMSPACE_TEST_DEMO names, and these copy a part's model folders from there. Run by hand,
// without that variable, each writes its part as demo:: does. A fixture folder that lacks a
// part's model is an error, never a silent rebuild: the fixture failed.
#pragma once

#include <filesystem>

#include "core/common/result.h"

namespace animspace::testing {

// demo::write_demo_repository's models: arm, arm-pmsc, arm-cross-pmsc, arm-animspace,
// arm-pmsc-engine.
Status write_demo_repository(const std::filesystem::path& repository);
// demo::write_demo_smooth's arm-smooth (write_demo_repository's arm-animspace is its input).
Status write_demo_smooth(const std::filesystem::path& repository);
// demo::write_demo_illumination's cornell, default options.
Status write_demo_illumination(const std::filesystem::path& repository);
// demo::write_demo_articulated's arm-articulated.
Status write_demo_articulated(const std::filesystem::path& repository);

}  // namespace animspace::testing

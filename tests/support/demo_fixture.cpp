#include "tests/support/demo_fixture.h"

#include <cstdlib>
#include <initializer_list>
#include <string>
#include <string_view>
#include <system_error>

#include "core/demo/demo_repository.h"

namespace animspace::testing {
namespace {

namespace fs = std::filesystem;

// Copies `models` from the fixture's folder into `repository`; `write` makes them when no fixture
// is named (the suite run by hand).
Status copy_or_write(const fs::path& repository, std::initializer_list<std::string_view> models,
                     Status (*write)(const fs::path&)) {
  const char* fixture = std::getenv("ANIMSPACE_TEST_DEMO");
  if (fixture == nullptr || *fixture == '\0') return write(repository);
  for (const std::string_view model : models) {
    const fs::path from = fs::path(fixture) / model;
    const fs::path to = repository / model;
    std::error_code error;
    if (!fs::is_directory(from, error)) {
      return Error{ErrorCode::kNotFound, "the integration_demo fixture has no " + from.string() +
                                             " (ANIMSPACE_TEST_DEMO): did `animspace demo-repository` fail?"};
    }
    fs::create_directories(to, error);
    if (!error) fs::copy(from, to, fs::copy_options::recursive | fs::copy_options::overwrite_existing, error);
    if (error) return Error{ErrorCode::kIo, "copying " + from.string() + " to " + to.string() + ": " + error.message()};
  }
  return {};
}

Status write_default_illumination(const fs::path& repository) { return demo::write_demo_illumination(repository); }

}  // namespace

Status write_demo_repository(const fs::path& repository) {
  return copy_or_write(repository,
                       {demo::kDemoModelName, demo::kDemoPmscModelName, demo::kDemoCrossPmscModelName,
                        demo::kDemoAnimationSpaceModelName, demo::kDemoPmscEngineModelName},
                       &demo::write_demo_repository);
}

Status write_demo_smooth(const fs::path& repository) {
  return copy_or_write(repository, {demo::kDemoSmoothModelName}, &demo::write_demo_smooth);
}

Status write_demo_illumination(const fs::path& repository) {
  return copy_or_write(repository, {demo::kDemoIlluminationModelName}, &write_default_illumination);
}

Status write_demo_articulated(const fs::path& repository) {
  return copy_or_write(repository, {demo::kDemoArticulatedModelName}, &demo::write_demo_articulated);
}

}  // namespace animspace::testing

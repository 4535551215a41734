#include "core/container/sections.h"

#include <array>
#include <utility>

namespace animspace::container {
namespace {

constexpr std::array<std::pair<ModelKind, const char*>, 4> kKindNames{{
    {ModelKind::kMeshSequence, "mesh_sequence"},
    {ModelKind::kPmsc, "pmsc"},
    {ModelKind::kCrossPmsc, "cross_pmsc"},
    {ModelKind::kAnimationSpace, "animation_space"},
}};

}  // namespace

const char* kind_name(ModelKind kind) {
  for (const auto& [k, name] : kKindNames) {
    if (k == kind) return name;
  }
  return "unknown";
}

Result<ModelKind> parse_kind(const std::string& name) {
  for (const auto& [kind, kind_string] : kKindNames) {
    if (name == kind_string) return kind;
  }
  return make_error(ErrorCode::kInvalidArgument,
                    "unknown model kind '" + name + "' (expected mesh_sequence, pmsc, cross_pmsc or animation_space)");
}

Error section_shape_error(const std::string& source, const std::string& section, const std::string& expected,
                          long actual_rows, long actual_cols) {
  return make_error(ErrorCode::kInvalidArgument, source + ": section '" + section + "' should be " + expected +
                                                     ", got " + std::to_string(actual_rows) + "×" +
                                                     std::to_string(actual_cols));
}

}  // namespace animspace::container

// What a model container holds, named once: the model kinds (metadata "kind") and the section
// names every module shares.
//
// A leaf: it depends on nothing but common/, so each module that writes or reads a container
// (pmsc, animspace, lod, model, demo) names the same sections without depending on the module
// that describes whole models (model/model_info.h). Sections that only one module reads and
// writes are named in that module's *_io.h (animspace.*, pmsc.*, lod.*); their shapes are in
// docs/FORMATS.md.
#pragma once

#include <string>

#include "core/common/result.h"

namespace animspace::container {

enum class ModelKind { kMeshSequence, kPmsc, kCrossPmsc, kAnimationSpace };

// Metadata value of "kind" for each ModelKind ("mesh_sequence", "pmsc", "cross_pmsc",
// "animation_space").
const char* kind_name(ModelKind kind);
// The kind named `name`. Errors: kInvalidArgument naming it and the kinds expected.
Result<ModelKind> parse_kind(const std::string& name);

namespace sections {
inline constexpr const char* kRestPoints = "mesh.rest_points";            // N×3 float32
inline constexpr const char* kFaces = "mesh.faces";                       // F×3 int32
inline constexpr const char* kSkeletonParents = "skeleton.parents";       // B×1 int32, -1 = root
inline constexpr const char* kSkeletonRest = "skeleton.rest_transforms";  // B×16 float64 (Ĝ_j)
inline constexpr const char* kSkinningWeights = "skinning.weights";       // N×B float32
inline constexpr const char* kSequenceFrames = "sequence.frames";         // F×(N·D) float32
inline constexpr const char* kSequenceBoneTransforms = "sequence.bone_transforms";  // F×(B·16) f64
// A texture atlas (core/atlas/atlas_io.h): chart of each face, UV of each face corner.
inline constexpr const char* kAtlasChartIds = "atlas.chart_ids";  // #F×1 int32
inline constexpr const char* kAtlasUvs = "atlas.uvs";             // #F×6 float64 (u0 v0 u1 v1 u2 v2)
}  // namespace sections

// The error every reader gives for a section of the wrong shape: kInvalidArgument
// "<source>: section '<section>' should be <expected>, got <rows>×<cols>".
Error section_shape_error(const std::string& source, const std::string& section, const std::string& expected,
                          long actual_rows, long actual_cols);

}  // namespace animspace::container

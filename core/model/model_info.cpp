#include "core/model/model_info.h"

#include "core/animspace/animspace_io.h"
#include "core/illumination/illumination_io.h"
#include "core/lod/lod_io.h"

namespace animspace::model {
namespace {

namespace sections = container::sections;
using container::section_shape_error;

// Shapes only of the skeleton-and-influences sections of an animation-space model over
// `point_count` points (an animation_space model, or a PMSC model's posing engine);
// animation_space::load validates the values (weights, bones, finiteness).
Status check_animation_space_shapes(const container::ModelContainer& model, int point_count, const std::string& what,
                                    const std::string& source) {
  if (!model.has_section(sections::kSkeletonParents)) {
    return make_error(ErrorCode::kInvalidArgument, source + ": " + what + " needs section 'skeleton.parents'");
  }
  auto offsets = model.int_matrix(animation_space::sections::kInfluenceOffsets, 1);
  if (!offsets) return offsets.error();
  if (offsets->rows() != point_count + 1L) {
    return section_shape_error(source, animation_space::sections::kInfluenceOffsets, std::to_string(point_count + 1) + "×1",
                       offsets->rows(), offsets->cols());
  }
  auto bones = model.int_matrix(animation_space::sections::kInfluenceBones, 1);
  if (!bones) return bones.error();
  auto positions = model.double_matrix(animation_space::sections::kPositions, 4);
  if (!positions) return positions.error();
  if (positions->rows() != bones->rows()) {
    return section_shape_error(source, animation_space::sections::kPositions, std::to_string(bones->rows()) + "×4",
                       positions->rows(), positions->cols());
  }
  return Status::Ok();
}

}  // namespace

Result<ModelInfo> describe(const container::ModelContainer& model, const std::string& source) {
  ModelInfo info;
  const std::string kind = model.metadata_value("kind");
  if (kind.empty()) {
    return make_error(ErrorCode::kInvalidArgument, source + ": metadata has no 'kind'");
  }
  auto parsed_kind = container::parse_kind(kind);
  if (!parsed_kind) return make_error(ErrorCode::kInvalidArgument, source + ": " + parsed_kind.error().message);
  info.kind = *parsed_kind;
  info.description = model.metadata_value("description");

  if (info.kind == ModelKind::kPmsc || info.kind == ModelKind::kCrossPmsc) {
    auto channels = model.metadata_int("pmsc.channels");
    if (!channels) return make_error(ErrorCode::kInvalidArgument, source + ": " + channels.error().message);
    if (*channels < 1) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata 'pmsc.channels' must be ≥ 1, got " + std::to_string(*channels));
    }
    info.channel_count = *channels;
  }

  // The rest mesh fixes N; every other per-point section must agree with it.
  auto rest = model.points(sections::kRestPoints);
  if (!rest) return rest.error();
  info.point_count = static_cast<int>(rest->rows());

  if (model.has_section(sections::kFaces)) {
    auto faces = model.faces(sections::kFaces);
    if (!faces) return faces.error();
    if (faces->size() > 0 && (faces->minCoeff() < 0 || faces->maxCoeff() >= info.point_count)) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": section 'mesh.faces' indexes vertices outside [0, " +
                            std::to_string(info.point_count) + ")");
    }
    info.face_count = static_cast<int>(faces->rows());
  }

  if (model.has_section(sections::kSkeletonParents)) {
    auto parents = model.int_matrix(sections::kSkeletonParents, 1);
    if (!parents) return parents.error();
    info.bone_count = static_cast<int>(parents->rows());
    for (int j = 0; j < info.bone_count; ++j) {
      // Bones are stored parents-first so that G_j = G_parent · L_j composes in one pass.
      const int parent = (*parents)(j, 0);
      if (parent < -1 || parent >= j) {
        return make_error(ErrorCode::kInvalidArgument,
                          source + ": section 'skeleton.parents' row " + std::to_string(j) +
                              " has parent " + std::to_string(parent) +
                              ", expected -1 or a bone index below " + std::to_string(j));
      }
    }
    auto rest_transforms = model.double_matrix(sections::kSkeletonRest, 16);
    if (!rest_transforms) return rest_transforms.error();
    if (rest_transforms->rows() != info.bone_count) {
      return section_shape_error(source, sections::kSkeletonRest, std::to_string(info.bone_count) + "×16",
                         rest_transforms->rows(), rest_transforms->cols());
    }
  }

  if (model.has_section(sections::kSkinningWeights)) {
    auto weights = model.float_matrix(sections::kSkinningWeights);
    if (!weights) return weights.error();
    if (weights->rows() != info.point_count || weights->cols() != info.bone_count) {
      return section_shape_error(source, sections::kSkinningWeights,
                         std::to_string(info.point_count) + "×" + std::to_string(info.bone_count),
                         weights->rows(), weights->cols());
    }
  }

  if (model.has_section(sections::kSequenceFrames)) {
    auto frames = model.float_matrix(sections::kSequenceFrames);
    if (!frames) return frames.error();
    if (frames->cols() != static_cast<long>(info.point_count) * info.channel_count) {
      return section_shape_error(source, sections::kSequenceFrames,
                         "F×" + std::to_string(static_cast<long>(info.point_count) * info.channel_count),
                         frames->rows(), frames->cols());
    }
    info.frame_count = static_cast<int>(frames->rows());
    if (model.has_section(sections::kSequenceBoneTransforms)) {
      auto bones = model.double_matrix(sections::kSequenceBoneTransforms);
      if (!bones) return bones.error();
      if (bones->rows() != info.frame_count || bones->cols() != 16L * info.bone_count) {
        return section_shape_error(source, sections::kSequenceBoneTransforms,
                           std::to_string(info.frame_count) + "×" + std::to_string(16 * info.bone_count),
                           bones->rows(), bones->cols());
      }
    }
  }
  if (info.kind == ModelKind::kAnimationSpace) {
    ANIMSPACE_RETURN_IF_ERROR(
        check_animation_space_shapes(model, info.point_count, "an animation_space model", source));
    if (model.has_section(lod::sections::kErrors)) {
      auto errors = model.double_matrix(lod::sections::kErrors, 1);
      if (!errors) return errors.error();
      info.lod_level_count = static_cast<int>(errors->rows());
    }
  }
  if (info.kind == ModelKind::kPmsc || info.kind == ModelKind::kCrossPmsc) {
    // Shapes only; pmsc::load validates everything and prepares the runtime.
    auto mean = model.float_matrix("pmsc.mean");
    if (!mean) return mean.error();
    if (mean->cols() != static_cast<long>(info.point_count) * info.channel_count) {
      return section_shape_error(source, "pmsc.mean",
                         "1×" + std::to_string(static_cast<long>(info.point_count) * info.channel_count),
                         mean->rows(), mean->cols());
    }
    auto basis = model.float_matrix("pmsc.basis");
    if (!basis) return basis.error();
    auto keys = model.int_matrix("pmsc.key_points", 1);
    if (!keys) return keys.error();
    auto epsilon = model.double_matrix("pmsc.epsilon", 2);
    if (!epsilon) return epsilon.error();
    // Read below as (ε_min, ε_max): any other row count is refused before that read.
    if (epsilon->rows() != 1) return section_shape_error(source, "pmsc.epsilon", "1×2", epsilon->rows(), epsilon->cols());
    info.basis_size = static_cast<int>(basis->cols());
    info.key_point_count = static_cast<int>(keys->rows());
    info.epsilon_min = static_cast<float>((*epsilon)(0, 0));
    info.epsilon_max = static_cast<float>((*epsilon)(0, 1));
    if (info.kind == ModelKind::kCrossPmsc) {
      // 2007 §3.1: the outputs have no full calculation at all.
      info.fail_through = FailThrough::kImpossible;
    } else if (model.has_section(animation_space::sections::kInfluenceOffsets)) {
      // A posing engine (pmsc_io.h, attach_posing_engine): an animation-space model of the same
      // points, from which the server computes the full values itself on a blend or miss.
      if (info.channel_count != 3) {
        return make_error(ErrorCode::kInvalidArgument,
                          source + ": a pmsc model with a posing engine (section 'animspace.influence_offsets') "
                                   "must have pmsc.channels = 3, got " + std::to_string(info.channel_count));
      }
      ANIMSPACE_RETURN_IF_ERROR(check_animation_space_shapes(model, info.point_count, "a posing engine", source));
      info.fail_through = FailThrough::kServer;
      info.server_engine = ServerEngine::kAnimationSpace;
    } else if (illumination::has_illumination(model)) {
      // An illumination engine (illumination_io.h): the surface the model's RGB radiance lives
      // on, from which the server gathers the full values itself for a request's lights
      // (illumination::load_illumination checks the sections when the model is made servable).
      if (info.channel_count != 3) {
        return make_error(ErrorCode::kInvalidArgument,
                          source + ": a pmsc model with an illumination engine (section '" +
                              illumination::sections::kAlbedo + "') must have pmsc.channels = 3 (RGB), got " +
                              std::to_string(info.channel_count));
      }
      info.fail_through = FailThrough::kServer;
      info.server_engine = ServerEngine::kIllumination;
    } else {
      info.fail_through = FailThrough::kClient;
    }
  }
  return info;
}

}  // namespace animspace::model

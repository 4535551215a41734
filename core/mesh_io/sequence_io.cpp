#include "core/mesh_io/sequence_io.h"

#include "core/common/nearest_names.h"

#include <cctype>
#include <string>

#include "core/mesh_io/obj_sequence.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::mesh_io {
namespace {

// What a sequence can be read from, for every message that turns a file away.
constexpr const char* kReadableSequences =
    "a sequence is read from a folder with reference.obj + frames.pc2, a folder of OBJ frames, or a mesh "
    "(OBJ, PLY, OFF) with its point cache (--pc2 FILE.pc2)";

// Caches of other tools that are not read here, and how to bring them over (issue #39).
const char* foreign_cache_name(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (extension == ".abc") return "an Alembic cache (.abc)";
  if (extension == ".usd" || extension == ".usda" || extension == ".usdc" || extension == ".usdz") {
    return "a USD stage";
  }
  if (extension == ".fbx") return "an FBX file";
  if (extension == ".mdd") return "an MDD point cache";
  if (extension == ".vdb") return "an OpenVDB volume";
  return nullptr;
}

// "PATH: no such file or folder", with the names in its folder a typo was probably meant to be
// (issue #55: a typo'd path got "a reference mesh needs a point cache").
Error missing(const std::filesystem::path& path) {
  std::string message = path.string() + ": no such file or folder";
  const std::filesystem::path folder = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) {
    return make_error(ErrorCode::kNotFound, message + " (nor the folder " + folder.string() + ")");
  }
  std::vector<std::string> names;
  for (std::filesystem::directory_iterator entry(folder, ec), end; !ec && entry != end; entry.increment(ec)) {
    names.push_back(entry->path().filename().string());
  }
  const std::vector<std::string> near = nearest_names(path.filename().string(), names);
  if (!near.empty()) {
    message += "; did you mean ";
    for (size_t i = 0; i < near.size(); ++i) message += (i == 0 ? "" : i + 1 == near.size() ? " or " : ", ") + (folder / near[i]).string();
    message += "?";
  }
  return make_error(ErrorCode::kNotFound, message);
}

}  // namespace

Result<LoadedSequence> load_sequence(const std::filesystem::path& path, const std::filesystem::path& pc2) {
  for (const std::filesystem::path& given : {path, pc2}) {
    if (const char* name = foreign_cache_name(given)) {
      return make_error(ErrorCode::kInvalidArgument,
                        given.string() + " is " + name + ", which is not read: " + kReadableSequences +
                            ". To convert, play it on the mesh in Blender (File › Import, or a Mesh Cache or Mesh "
                            "Sequence Cache modifier; Alembic and USD need a Blender built with them, which Debian's "
                            "is not) and send it with the animspace add-on's Train from animation (sidebar › "
                            "animspace), which runs this command on its evaluated animation; or export the mesh as "
                            "OBJ with its animation as a Point Cache (.pc2)");
    }
  }
  std::error_code ec;
  for (const std::filesystem::path& given : {path, pc2}) {
    if (!given.empty() && !std::filesystem::exists(given, ec)) return missing(given);
  }
  std::filesystem::path reference_path = path;
  std::filesystem::path cache_path = pc2;
  if (std::filesystem::is_directory(path, ec)) {
    if (std::filesystem::exists(path / "reference.obj", ec) && std::filesystem::exists(path / "frames.pc2", ec)) {
      reference_path = path / "reference.obj";
      cache_path = path / "frames.pc2";
    } else {
      auto files = list_obj_sequence(path);
      if (!files) return files.error();
      auto sequence = read_obj_sequence(*files);
      if (!sequence) return sequence.error();
      LoadedSequence out;
      out.reference.F = sequence->F;
      out.reference.V = sequence->frames.frame(0);
      out.frames = std::move(sequence->frames);
      return out;
    }
  }
  if (cache_path.empty()) {
    return make_error(ErrorCode::kInvalidArgument,
                      path.string() + ": a reference mesh needs a point cache (.pc2) to form a sequence; " +
                          kReadableSequences);
  }
  auto reference = read_triangle_mesh(reference_path);
  if (!reference) return reference.error();
  auto frames = read_pc2(cache_path);
  if (!frames) return frames.error();
  if (frames->num_points != reference->V.rows()) {
    return make_error(ErrorCode::kInvalidArgument,
                      cache_path.string() + " has " + std::to_string(frames->num_points) + " points but " +
                          reference_path.string() + " has " + std::to_string(reference->V.rows()) + " vertices");
  }
  return LoadedSequence{std::move(*reference), std::move(*frames)};
}

}  // namespace animspace::mesh_io

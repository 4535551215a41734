// The model repository on disk: <repository>/<model>/<version>/model.anim, versions positive
// decimal integers. Shared by the daemon (loading, polling, Retrain publishing) and the offline
// tools that publish versions into a repository a daemon is serving (`animspace retrain-offline`).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::model {

inline constexpr const char* kModelFileName = "model.anim";
inline constexpr size_t kMaxModelNameLength = 128;

// Model names are directory names chosen by people; anything that could escape the repository
// or hide a file ('..', '/', a leading '.') is refused. Errors: kInvalidArgument naming `field`
// and the rule.
Status validate_model_name(std::string_view name, std::string_view field = "model.name");

// A version directory name: a positive decimal integer without sign or leading zeros.
bool parse_version(const std::string& text, uint64_t* version);

// The version directories of one model, ascending. Errors: kNotFound when the model has no
// directory; kIo when it cannot be listed.
Result<std::vector<uint64_t>> list_versions(const std::filesystem::path& repository, const std::string& name);

// Whether `path` — a model's folder, a version's folder, its model.anim — is inside `repository`
// with every symbolic link resolved (issue #54): a link out of it (to another user's files, to
// /etc) is refused before anything is read, so the daemon serves, and reports the bytes of, only
// what the repository holds. Links within the repository are followed. Errors: kFailedPrecondition
// naming the path and where it leads; kNotFound or kIo when it cannot be resolved.
Status check_inside_repository(const std::filesystem::path& repository, const std::filesystem::path& path);

// Writes `model` as the next version (one above the newest present, 1 for a new model) so that
// nobody ever sees it half-written: into a hidden staging directory first, then renamed into
// place — a daemon polling the repository sees either no version or the complete one. Callers
// publishing the same model concurrently from one process must serialise; across processes the
// rename fails rather than overwrite (kIo). Returns the version written.
Result<uint64_t> publish_version(const std::filesystem::path& repository, const std::string& name,
                                 const container::ModelContainer& model);

}  // namespace animspace::model

#include "clients/cpp/coordinates.h"

#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "core/common/atomic_file.h"
#include "core/common/bytes.h"
#include "core/common/sha256.h"
#include "core/pmsc/coordinates.h"

namespace animspace {
namespace {

// The cache file (docs/FORMATS.md, "basis cache"): magic, N, D, M, aligned (uint32 each),
// version, checksum (uint64 each), then the float32 values as GetBasis sends them. A skinned
// basis: its own magic, and layout, B, K and a reserved word (uint32 each) before the values.
constexpr std::string_view kMagic = "ASBASIS1";
constexpr std::string_view kSkinnedMagic = "ASBASIS2";
constexpr size_t kHeaderBytes = 40;
constexpr size_t kSkinnedHeaderBytes = 56;

std::string hex16(uint64_t value) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(value));
  return text;
}

}  // namespace

size_t Basis::bytes() const {
  const size_t values = static_cast<size_t>(mean.size() + basis.size()) +
                        (skinned ? static_cast<size_t>(skinned->mean.size() + skinned->residuals.size()) +
                                       skinned->terms.size()
                                 : 0);
  return sizeof(float) * values + (skinned ? sizeof(int32_t) * skinned->bones.size() : 0);
}

Basis make_basis(const std::string& model, BasisData data) {
  const auto rows = static_cast<long>(data.point_count) * data.channel_count;
  const long columns = data.basis_size;
  const std::string named = "basis of '" + model + "' version " + std::to_string(data.model_version);
  std::shared_ptr<const pmsc::SkinnedBasis> skinned;
  if (data.layout == v1::BASIS_LAYOUT_SKINNED) {
    auto parsed = pmsc::skinned_basis_from_values(data.values, data.point_count,
                                                  static_cast<int>(data.subspace_bone_count),
                                                  static_cast<int>(data.influences_per_point), columns);
    if (!parsed) throw std::runtime_error(named + ": " + parsed.error().message);
    skinned = std::make_shared<const pmsc::SkinnedBasis>(std::move(*parsed));
  } else if (data.values.size() != static_cast<size_t>(rows * (columns + 1))) {
    throw std::runtime_error("basis of '" + model + "' version " + std::to_string(data.model_version) + ": " +
                             std::to_string(data.values.size()) + " values, expected N·D·(M+1) = " +
                             std::to_string(rows * (columns + 1)));
  }
  if (data.aligned && data.channel_count != 3) {
    throw std::runtime_error("basis of '" + model + "': aligned with " + std::to_string(data.channel_count) +
                             " channels (alignment moves 3-channel points)");
  }
  Basis basis;
  basis.model = model;
  basis.model_version = data.model_version;
  basis.basis_checksum = data.basis_checksum;
  basis.channel_count = data.channel_count;
  basis.aligned = data.aligned;
  basis.mean = Eigen::Map<const Eigen::VectorXf>(data.values.data(), rows);
  if (skinned) {
    basis.skinned = skinned;
  } else {
    basis.basis = Eigen::Map<const Eigen::MatrixXf>(data.values.data() + rows, rows, columns);
  }
  if (data.values_encoding == v1::POINT_ENCODING_FLOAT16) {
    basis.basis_sha256 = std::move(data.basis_sha256);
    basis.values_max_error = data.values_max_error;
    return basis;
  }
  const uint64_t computed = skinned ? pmsc::basis_checksum(*skinned) : pmsc::basis_checksum(basis.mean, basis.basis);
  if (computed != data.basis_checksum) {
    throw std::runtime_error(named + ": its values have checksum " + hex16(computed) + ", the server named " +
                             hex16(data.basis_checksum));
  }
  if (!data.basis_sha256.empty()) {
    const std::string digest = skinned ? pmsc::basis_sha256(*skinned) : pmsc::basis_sha256(basis.mean, basis.basis);
    if (digest != data.basis_sha256) {
      throw std::runtime_error(named + ": its values have SHA-256 " + hex_digest(digest) + ", the server named " +
                               hex_digest(data.basis_sha256));
    }
    basis.basis_sha256 = std::move(data.basis_sha256);
  }
  return basis;
}

void reconstruct(const Basis& basis, const PoseResult& result, Points& out) {
  const SubspaceCoordinates& c = result.coordinates;
  if (!c.present) throw std::runtime_error("the result carries no coordinates (points_encoding was not COORDINATES)");
  if (c.basis_checksum != basis.basis_checksum) {
    throw std::runtime_error("coordinates of '" + basis.model + "' version " + std::to_string(result.model_version) +
                             " belong to basis " + hex16(c.basis_checksum) + ", not to the one given (" +
                             hex16(basis.basis_checksum) + ")");
  }
  const size_t alignment_values = basis.aligned ? 12 : 0;
  if (c.p.size() != static_cast<size_t>(basis.basis_size()) ||
      c.rotation.size() + c.translation.size() != alignment_values) {
    throw std::runtime_error("coordinates of '" + basis.model + "': " + std::to_string(c.p.size()) + " values and " +
                             std::to_string(c.rotation.size() + c.translation.size()) +
                             " alignment values, expected " + std::to_string(basis.basis_size()) + " and " +
                             std::to_string(alignment_values));
  }
  pmsc::FloatAlignment alignment;
  if (basis.aligned) {
    alignment.rotation = Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>>(c.rotation.data());
    alignment.translation = Eigen::Map<const Eigen::Vector3f>(c.translation.data());
  }
  out.channel_count = basis.channel_count;
  out.point_count = static_cast<uint32_t>(basis.mean.size() / basis.channel_count);
  out.max_error = 0;
  out.values.resize(static_cast<size_t>(basis.mean.size()));
  if (basis.skinned) {
    pmsc::reconstruct_coordinates(*basis.skinned, c.p.data(), basis.aligned ? &alignment : nullptr, out.values.data());
  } else {
    pmsc::reconstruct_coordinates(basis.mean, basis.basis, c.p.data(), basis.aligned ? &alignment : nullptr,
                                  out.values.data());
  }
}

std::filesystem::path default_basis_cache_directory() {
  if (const char* set = std::getenv("ANIMSPACE_BASIS_CACHE"); set != nullptr && *set != '\0') return set;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0') {
    return std::filesystem::path(xdg) / "animspace" / "bases";
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    return std::filesystem::path(home) / ".cache" / "animspace" / "bases";
  }
  return std::filesystem::temp_directory_path() / "animspace-bases";
}

BasisCache::BasisCache(std::filesystem::path directory, size_t memory_limit_bytes)
    : directory_(std::move(directory)), memory_limit_bytes_(memory_limit_bytes) {}

std::filesystem::path BasisCache::file_of(const std::string& model, uint64_t version, uint64_t checksum) const {
  return directory_ / model / (std::to_string(version) + "-" + hex16(checksum) + ".basis");
}

std::shared_ptr<const Basis> BasisCache::read_file(Client& client, const std::string& model, uint64_t version,
                                                   uint64_t checksum) const {
  if (directory_.empty()) return nullptr;
  const auto path = file_of(model, version, checksum);
  auto bytes = read_regular_file(path);  // a FIFO in its place would hang the client (issue #54)
  if (!bytes || bytes->size() < kHeaderBytes) return nullptr;
  const std::string_view view(*bytes);
  const bool skinned = view.substr(0, kSkinnedMagic.size()) == kSkinnedMagic;
  if (!skinned && view.substr(0, kMagic.size()) != kMagic) return nullptr;
  const size_t header = skinned ? kSkinnedHeaderBytes : kHeaderBytes;
  if (bytes->size() < header) return nullptr;
  BasisData data;
  data.point_count = load_le<uint32_t>(view, 8);
  data.channel_count = load_le<uint32_t>(view, 12);
  data.basis_size = load_le<uint32_t>(view, 16);
  data.aligned = load_le<uint32_t>(view, 20) != 0;
  data.model_version = load_le<uint64_t>(view, 24);
  data.basis_checksum = load_le<uint64_t>(view, 32);
  uint64_t values = uint64_t{data.point_count} * data.channel_count * (uint64_t{data.basis_size} + 1);
  if (skinned) {
    data.layout = v1::BASIS_LAYOUT_SKINNED;
    data.subspace_bone_count = load_le<uint32_t>(view, 44);
    data.influences_per_point = load_le<uint32_t>(view, 48);
    const uint64_t B = data.subspace_bone_count, K = data.influences_per_point, N = data.point_count;
    if (load_le<uint32_t>(view, 40) != v1::BASIS_LAYOUT_SKINNED || 12 * B > data.basis_size) return nullptr;
    values = 3 * N * (data.basis_size - 12 * B + 1) + pmsc::kSlotValues * N * K;
  }
  if (data.model_version != version || data.basis_checksum != checksum ||
      bytes->size() != header + values * sizeof(float)) {
    return nullptr;
  }
  data.values.resize(values);
  std::memcpy(data.values.data(), bytes->data() + header, values * sizeof(float));
  // The server's word on the version: its checksum must be the one asked for (else the answer
  // named a basis the version no longer has, and GetBasis says so), its digest the copy's.
  KeyPoints described;
  try {
    described = client.describe_key_points(model, version);
  } catch (const RpcError&) {
    return nullptr;  // the version is gone: GetBasis names the problem
  }
  // (A server from before issue #54 names neither: the CRC check alone, as then.)
  if (!described.basis_sha256.empty() && described.basis_checksum != checksum) return nullptr;
  data.basis_sha256 = described.basis_sha256;
  try {
    return std::make_shared<const Basis>(make_basis(model, std::move(data)));
  } catch (const std::runtime_error&) {
    refused_copies_ += 1;
    return nullptr;  // corrupt or tampered with: fetched again, and overwritten
  }
}

void BasisCache::write_file(const Basis& basis) const {
  if (directory_.empty()) return;
  const auto rows = static_cast<size_t>(basis.mean.size());
  const size_t header = basis.skinned ? kSkinnedHeaderBytes : kHeaderBytes;
  std::vector<float> skinned_values;
  if (basis.skinned) skinned_values = pmsc::skinned_values(*basis.skinned);
  const size_t values = basis.skinned ? skinned_values.size() : rows * (static_cast<size_t>(basis.basis.cols()) + 1);
  std::string bytes(header + values * sizeof(float), '\0');
  std::memcpy(bytes.data(), (basis.skinned ? kSkinnedMagic : kMagic).data(), kMagic.size());
  store_le<uint32_t>(bytes, 8, static_cast<uint32_t>(rows / basis.channel_count));
  store_le<uint32_t>(bytes, 12, basis.channel_count);
  store_le<uint32_t>(bytes, 16, static_cast<uint32_t>(basis.basis_size()));
  store_le<uint32_t>(bytes, 20, basis.aligned ? 1 : 0);
  store_le<uint64_t>(bytes, 24, basis.model_version);
  store_le<uint64_t>(bytes, 32, basis.basis_checksum);
  if (basis.skinned) {
    store_le<uint32_t>(bytes, 40, v1::BASIS_LAYOUT_SKINNED);
    store_le<uint32_t>(bytes, 44, static_cast<uint32_t>(basis.skinned->bone_count));
    store_le<uint32_t>(bytes, 48, static_cast<uint32_t>(basis.skinned->influences));
    std::memcpy(bytes.data() + header, skinned_values.data(), values * sizeof(float));
  } else {
    std::memcpy(bytes.data() + header, basis.mean.data(), rows * sizeof(float));
    std::memcpy(bytes.data() + header + rows * sizeof(float), basis.basis.data(),
                rows * static_cast<size_t>(basis.basis.cols()) * sizeof(float));
  }
  const auto path = file_of(basis.model, basis.model_version, basis.basis_checksum);
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  // A cache that cannot be written only costs the next process a download.
  (void)write_file_atomically(path, bytes);
}

std::shared_ptr<const Basis> BasisCache::get(Client& client, const std::string& model, uint64_t version,
                                             uint64_t checksum) {
  const Key key = std::make_tuple(model, version, checksum);
  {
    std::lock_guard lock(mutex_);
    if (auto found = bases_.find(key); found != bases_.end()) {
      recency_.splice(recency_.begin(), recency_, found->second.position);
      return found->second.basis;
    }
  }
  std::shared_ptr<const Basis> basis = read_file(client, model, version, checksum);
  if (!basis) {
    fetches_ += 1;
    auto fetched = std::make_shared<const Basis>(make_basis(
        model, client.get_basis(model, version, {}, v1::POINT_ENCODING_FLOAT32, v1::BASIS_LAYOUT_COMPACT)));
    if (fetched->model_version != version || fetched->basis_checksum != checksum) {
      throw std::runtime_error("model '" + model + "' version " + std::to_string(version) + ": the server's basis is " +
                               hex16(fetched->basis_checksum) + " (version " + std::to_string(fetched->model_version) +
                               "), the answer names " + hex16(checksum) +
                               " — the version was replaced since it answered; evaluate the pose again");
    }
    write_file(*fetched);
    basis = std::move(fetched);
  }
  std::lock_guard lock(mutex_);
  return keep(key, std::move(basis));
}

std::shared_ptr<const Basis> BasisCache::keep(const Key& key, std::shared_ptr<const Basis> basis) {
  if (auto found = bases_.find(key); found != bases_.end()) {  // another caller got it meanwhile
    recency_.splice(recency_.begin(), recency_, found->second.position);
    return found->second.basis;
  }
  recency_.push_front(key);
  bytes_ += basis->bytes();
  bases_.emplace(key, Held{basis, recency_.begin()});
  while (recency_.size() > 1 && bytes_ > memory_limit_bytes_) {
    const auto oldest = bases_.find(recency_.back());
    bytes_ -= oldest->second.basis->bytes();
    bases_.erase(oldest);
    recency_.pop_back();
  }
  return basis;
}

size_t BasisCache::memory_count() const {
  std::lock_guard lock(mutex_);
  return bases_.size();
}

size_t BasisCache::memory_bytes() const {
  std::lock_guard lock(mutex_);
  return bytes_;
}

bool BasisCache::reconstruct(Client& client, const std::string& model, PoseResult& result) {
  if (!result.coordinates.present) return false;
  const auto basis = get(client, model, result.model_version, result.coordinates.basis_checksum);
  animspace::reconstruct(*basis, result, result.points);
  return true;
}

}  // namespace animspace

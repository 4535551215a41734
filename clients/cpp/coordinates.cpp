#include "clients/cpp/coordinates.h"

#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <stdexcept>
#include <string_view>

#include "core/common/atomic_file.h"
#include "core/common/bytes.h"
#include "core/common/sha256.h"
#include "core/pmsc/coordinates.h"

namespace animspace {
namespace {

// The cache file (docs/FORMATS.md, "basis cache"): magic, N, D, M, aligned (uint32 each),
// version, checksum (uint64 each), then the float32 values as GetBasis sends them.
constexpr std::string_view kMagic = "ASBASIS1";
constexpr size_t kHeaderBytes = 40;

std::string hex16(uint64_t value) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(value));
  return text;
}

}  // namespace

Basis make_basis(const std::string& model, BasisData data) {
  const auto rows = static_cast<long>(data.point_count) * data.channel_count;
  const long columns = data.basis_size;
  if (data.values.size() != static_cast<size_t>(rows * (columns + 1))) {
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
  basis.basis = Eigen::Map<const Eigen::MatrixXf>(data.values.data() + rows, rows, columns);
  if (data.values_encoding == v1::POINT_ENCODING_FLOAT16) {
    basis.basis_sha256 = std::move(data.basis_sha256);
    basis.values_max_error = data.values_max_error;
    return basis;
  }
  const uint64_t computed = pmsc::basis_checksum(basis.mean, basis.basis);
  if (computed != data.basis_checksum) {
    throw std::runtime_error("basis of '" + model + "' version " + std::to_string(data.model_version) +
                             ": its values have checksum " + hex16(computed) + ", the server named " +
                             hex16(data.basis_checksum));
  }
  if (!data.basis_sha256.empty()) {
    const std::string digest = pmsc::basis_sha256(basis.mean, basis.basis);
    if (digest != data.basis_sha256) {
      throw std::runtime_error("basis of '" + model + "' version " + std::to_string(data.model_version) +
                               ": its values have SHA-256 " + hex_digest(digest) + ", the server named " +
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
  if (c.p.size() != static_cast<size_t>(basis.basis.cols()) ||
      c.rotation.size() + c.translation.size() != alignment_values) {
    throw std::runtime_error("coordinates of '" + basis.model + "': " + std::to_string(c.p.size()) + " values and " +
                             std::to_string(c.rotation.size() + c.translation.size()) +
                             " alignment values, expected " + std::to_string(basis.basis.cols()) + " and " +
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
  pmsc::reconstruct_coordinates(basis.mean, basis.basis, c.p.data(), basis.aligned ? &alignment : nullptr,
                                out.values.data());
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
  if (!bytes || bytes->size() < kHeaderBytes || std::string_view(*bytes).substr(0, kMagic.size()) != kMagic) {
    return nullptr;
  }
  const std::string_view view(*bytes);
  BasisData data;
  data.point_count = load_le<uint32_t>(view, 8);
  data.channel_count = load_le<uint32_t>(view, 12);
  data.basis_size = load_le<uint32_t>(view, 16);
  data.aligned = load_le<uint32_t>(view, 20) != 0;
  data.model_version = load_le<uint64_t>(view, 24);
  data.basis_checksum = load_le<uint64_t>(view, 32);
  const uint64_t values = uint64_t{data.point_count} * data.channel_count * (uint64_t{data.basis_size} + 1);
  if (data.model_version != version || data.basis_checksum != checksum ||
      bytes->size() != kHeaderBytes + values * sizeof(float)) {
    return nullptr;
  }
  data.values.resize(values);
  std::memcpy(data.values.data(), bytes->data() + kHeaderBytes, values * sizeof(float));
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
  const auto values = rows * (static_cast<size_t>(basis.basis.cols()) + 1);
  std::string bytes(kHeaderBytes + values * sizeof(float), '\0');
  std::memcpy(bytes.data(), kMagic.data(), kMagic.size());
  store_le<uint32_t>(bytes, 8, static_cast<uint32_t>(rows / basis.channel_count));
  store_le<uint32_t>(bytes, 12, basis.channel_count);
  store_le<uint32_t>(bytes, 16, static_cast<uint32_t>(basis.basis.cols()));
  store_le<uint32_t>(bytes, 20, basis.aligned ? 1 : 0);
  store_le<uint64_t>(bytes, 24, basis.model_version);
  store_le<uint64_t>(bytes, 32, basis.basis_checksum);
  std::memcpy(bytes.data() + kHeaderBytes, basis.mean.data(), rows * sizeof(float));
  std::memcpy(bytes.data() + kHeaderBytes + rows * sizeof(float), basis.basis.data(),
              rows * static_cast<size_t>(basis.basis.cols()) * sizeof(float));
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
    auto fetched = std::make_shared<const Basis>(make_basis(model, client.get_basis(model, version)));
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

namespace {
size_t bytes_of(const Basis& basis) {
  return sizeof(float) * static_cast<size_t>(basis.mean.size() + basis.basis.size());
}
}  // namespace

std::shared_ptr<const Basis> BasisCache::keep(const Key& key, std::shared_ptr<const Basis> basis) {
  if (auto found = bases_.find(key); found != bases_.end()) {  // another caller got it meanwhile
    recency_.splice(recency_.begin(), recency_, found->second.position);
    return found->second.basis;
  }
  recency_.push_front(key);
  bytes_ += bytes_of(*basis);
  bases_.emplace(key, Held{basis, recency_.begin()});
  while (recency_.size() > 1 && bytes_ > memory_limit_bytes_) {
    const auto oldest = bases_.find(recency_.back());
    bytes_ -= bytes_of(*oldest->second.basis);
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

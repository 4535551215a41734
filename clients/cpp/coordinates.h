// Point multiplication on the client (issue #36): answers asked for as POINT_ENCODING_COORDINATES
// carry p (M values) instead of N·D points, and the client reconstructs
//   f̂_i = R (mean_i + Σ_j A_ij p_j) + t
// with the basis PoseService.GetBasis sent once — with the project's own one-pose reconstruction
// (pmsc::reconstruct_coordinates, core/pmsc/coordinates.h), so this library links the core
// library beside the stub-only animspace_client.
//
// Bound (tested): a reconstruction here and the server's float32 answer for the same pose differ
// in value i by at most
//   pmsc::coordinates_rounding_bound(M) · (|mean_i| + Σ_j |A_ij p_j|)
// (both sums within γ_{M+2} of the exact one; 0 when both run the same kernel on one pose) and,
// for an aligned model, that error's norm over the point plus pmsc::aligned_rounding_bound() · ‖x‖
// + pmsc::translation_rounding_bound() · |f̂_c| per coordinate c of a point x (aligned frame).
//
// Never silently wrong: every answer names its basis (basis_checksum). A basis is looked up by
// model, the answer's version and that checksum — in memory, then on disk, then with GetBasis for
// exactly that version (its SHA-256 checked against the one the server sent, then stored). What
// the disk cache promises (issue #54 item 8): a copy read back is the basis the server serves for
// that version, or it is not used. Its CRC catches accidents only (a CRC-32 is forged in four
// bytes), so a copy from disk is used only after its values' SHA-256 matches the one the server
// names for the version (DescribeKeyPoints: one small call instead of the basis); one that does
// not match is fetched again and overwritten. A server from before that digest gets the CRC
// check alone. A server whose basis for that
// version has another checksum (the version was replaced), or a result whose shape differs from
// its basis, is refused with std::runtime_error; the points are never reconstructed with a basis
// the answer did not name.
//
// The disk cache is shared with the Python client (docs/FORMATS.md, "basis cache"):
// <directory>/<model>/<version>-<checksum, 16 hex digits>.basis, dense (ASBASIS1) or skinned
// (ASBASIS2). The cache asks GetBasis for the COMPACT layout: an articulated model's basis comes
// and stays skinned.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>

#include <Eigen/Core>

#include "clients/cpp/client.h"
#include "clients/cpp/results.h"
#include "core/pmsc/skinned_basis.h"

namespace animspace {

// A model version's subspace, ready to reconstruct with: the dense basis, or an articulated
// model's skinned form of it (GetBasisRequest.layout SKINNED, issue #51 item 4), which is the same
// basis — the same checksum and SHA-256 — in a fraction of the memory (a tenth with tens of
// bones), reconstructed within the same bound.
struct Basis {
  std::string model;
  uint64_t model_version = 0;
  uint64_t basis_checksum = 0;
  std::string basis_sha256;  // 32 raw bytes; empty when its server sent none
  uint32_t channel_count = 0;
  bool aligned = false;
  Eigen::VectorXf mean;   // N·D
  Eigen::MatrixXf basis;  // N·D × M; empty when `skinned` holds it
  std::shared_ptr<const pmsc::SkinnedBasis> skinned;
  // 0 for the float32 basis; for one fetched as FLOAT16, the largest |value − float32 value|.
  // Each value is within 2^-11 of its own size, so reconstruct() is within about
  // 2^-11·(|mean_i| + Σ_j |A_ij p_j|) more per value (BasisChunk.values_max_error states it exactly).
  float values_max_error = 0;

  long basis_size() const { return skinned ? skinned->basis_size() : basis.cols(); }  // M
  size_t bytes() const;  // of the values held
};

// `data` (from Client::get_basis) as a Basis, after checking that its values have the checksum
// the server named (pmsc::basis_checksum) and, when it named one, the SHA-256
// (pmsc::basis_sha256) — a skinned basis through the dense values it expands to. std::runtime_error naming both when they differ. FLOAT16 data, checked
// as it came by get_basis, keeps the names of the float32 basis its answers belong to; a
// BasisCache holds only float32 bases.
Basis make_basis(const std::string& model, BasisData data);

// The points of `result` (its coordinates) reconstructed with `basis` into `out` (N×D float32).
// std::runtime_error when the coordinates name another basis, or their sizes do not fit it.
void reconstruct(const Basis& basis, const PoseResult& result, Points& out);

// $ANIMSPACE_BASIS_CACHE, else $XDG_CACHE_HOME/animspace/bases, else ~/.cache/animspace/bases
// (else a folder under the temporary directory when HOME is unset).
std::filesystem::path default_basis_cache_directory();

// The bases of the models a client takes coordinates from, in memory and on disk. Thread-safe:
// one cache may serve every caller of a client. At most `memory_limit_bytes` of bases stay in
// memory (as the Python client's BasisCache): the least recently used go first, the one just used
// always stays; an evicted basis comes back from disk, else from GetBasis.
class BasisCache {
 public:
  // An empty `directory` keeps bases in memory only.
  explicit BasisCache(std::filesystem::path directory = default_basis_cache_directory(),
                      size_t memory_limit_bytes = size_t{1} << 30);

  // The basis of `model` version `version` named `checksum` (see the header comment).
  std::shared_ptr<const Basis> get(Client& client, const std::string& model, uint64_t version, uint64_t checksum);
  // Fills result.points from result.coordinates (false, untouched, when it has none).
  bool reconstruct(Client& client, const std::string& model, PoseResult& result);

  // Where the basis named so lies on disk.
  std::filesystem::path file_of(const std::string& model, uint64_t version, uint64_t checksum) const;
  // GetBasis calls this cache made (a basis found in memory or on disk makes none), and copies
  // on disk refused because their values were not what the server names.
  uint64_t fetch_count() const { return fetches_.load(); }
  uint64_t refused_copy_count() const { return refused_copies_.load(); }
  // Bases held in memory now, and their bytes (mean and basis values).
  size_t memory_count() const;
  size_t memory_bytes() const;

 private:
  // The copy on disk, if any, once the server vouches for it (see the header comment).
  std::shared_ptr<const Basis> read_file(Client& client, const std::string& model, uint64_t version,
                                         uint64_t checksum) const;
  void write_file(const Basis& basis) const;

  using Key = std::tuple<std::string, uint64_t, uint64_t>;
  // Holds `basis` under `key` as the most recently used, then evicts down to the limit. Locked.
  std::shared_ptr<const Basis> keep(const Key& key, std::shared_ptr<const Basis> basis);

  const std::filesystem::path directory_;
  const size_t memory_limit_bytes_;
  mutable std::mutex mutex_;
  std::list<Key> recency_;  // most recently used first
  struct Held {
    std::shared_ptr<const Basis> basis;
    std::list<Key>::iterator position;
  };
  std::map<Key, Held> bases_;
  size_t bytes_ = 0;
  std::atomic<uint64_t> fetches_{0};
  mutable std::atomic<uint64_t> refused_copies_{0};
};

}  // namespace animspace

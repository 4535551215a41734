// Fuzz target: mesh_io::parse_dmat (libigl's dense matrix, text and binary variants).
#include "core/mesh_io/libigl_rig.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  const auto matrix = mesh_io::parse_dmat(fuzz::as_bytes(data, size), "fuzz.dmat");
  if (!matrix) {
    fuzz::check_refusal(matrix.error(), "fuzz.dmat");
    return 0;
  }
  // Text values take at least two bytes each and binary ones eight: a matrix larger than the
  // input would mean the header's counts were trusted.
  FUZZ_CHECK(static_cast<size_t>(matrix->size()) <= size);
  // (Eigen's allFinite walks every column, even of a 0 × 2^31 matrix: skip the empty ones.)
  FUZZ_CHECK(matrix->size() == 0 || matrix->allFinite());
  return 0;
}

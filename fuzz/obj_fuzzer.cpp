// Fuzz target: mesh_io::parse_obj (OBJ text); the checks are in fuzz/mesh_invariants.h.
#include "fuzz/mesh_invariants.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  fuzz::fuzz_mesh_parser(fuzz::as_bytes(data, size), mesh_io::parse_obj, mesh_io::serialize_obj, "fuzz.obj");
  return 0;
}

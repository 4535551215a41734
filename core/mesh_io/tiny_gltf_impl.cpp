// The one translation unit that compiles tinygltf (Debian's libtinygltf-dev ships it as a header
// library; compiling it here keeps the daemon free of a runtime libtinygltf.so dependency).
// Its configuration (no stb_image, no external images) is set for all of animspace_core in
// core/CMakeLists.txt, so every file including <tiny_gltf.h> sees the same declarations.
// import.cpp installs an image loader that skips images, and catches whatever tinygltf or
// nlohmann::json might throw, so nothing escapes core.
#define TINYGLTF_IMPLEMENTATION
#include <tiny_gltf.h>

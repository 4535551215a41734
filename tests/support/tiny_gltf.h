// tinygltf for tests that read glTF files directly, declared with the configuration of the one
// translation unit that compiles it (core/mesh_io/tiny_gltf_impl.cpp, core/mesh_io/CMakeLists.txt),
// so that the declarations here match the compiled code.
#pragma once

#ifndef TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE
#endif
#ifndef TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#endif
#ifndef TINYGLTF_NO_EXTERNAL_IMAGE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#endif
#include <tiny_gltf.h>

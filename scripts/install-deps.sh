#!/usr/bin/env bash
# Installs every Debian package that the build, the tests and the demo need.
# Idempotent: packages already present are skipped, and apt is not touched at all
# when nothing is missing. Debian's archive is the only source; nothing else is downloaded.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git
  # the linker (CMakeLists.txt: lld links the test programs several times faster than GNU ld)
  lld
  # RPC
  libgrpc++-dev libgrpc-dev protobuf-compiler protobuf-compiler-grpc libprotobuf-dev grpc-proto
  # core numerics and geometry
  libeigen3-dev libopenblas-pthread-dev libopenmesh-dev libmeshoptimizer-dev libtinygltf-dev nlohmann-json3-dev libstb-dev
  # indirect illumination (core/illumination): Embree 3 ray tracing
  libembree-dev
  # subdivision in animation space (core/subdivision): OpenSubdiv builds the stencils S of P' = P S
  libosd-dev
  # server and command line
  libspdlog-dev libfmt-dev libcli11-dev libcpp-httplib-dev
  # the model file's CRC-32 (core/container/crc32)
  zlib1g-dev
  # SHA-256 of served bases, against which clients check their cached copies (core/common/sha256)
  libssl-dev
  # headless rendering (Mesa's surfaceless EGL, llvmpipe) and PNG
  libegl-dev libgles-dev libegl1 libgles2 libegl-mesa0 libgl1-mesa-dri libpng-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev openssl
  # fuzz/: libFuzzer targets (clang with its runtime: fuzzer, ASan, UBSan)
  clang libclang-rt-14-dev
  # Python client (always run with /usr/bin/python3)
  python3 python3-grpcio python3-protobuf python3-numpy python3-pytest python3-matplotlib
  # ... and its offline install from pyproject.toml into a --system-site-packages venv (tested:
  # the README's lines, pip --no-build-isolation)
  python3-pip python3-setuptools python3-wheel python3-venv
  # deploy/: manifests parsed and linted by the tests
  python3-yaml yamllint
  # clients/blender: the add-on is tested headless in Debian's Blender (3.4, on the system Python 3.11,
  # which imports python3-grpcio, python3-protobuf and python3-numpy above)
  blender
)

# The container image builds the daemon only; it has no use for Blender's ~500 MB.
if [ "${ANIMSPACE_WITHOUT_BLENDER:-0}" = "1" ]; then
  packages=("${packages[@]/blender}")
fi

missing=()
for p in "${packages[@]}"; do
  [ -n "$p" ] || continue
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"

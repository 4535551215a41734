"""Build hooks for the animspace package; the metadata lives in pyproject.toml.

The ``animspace.v1`` messages and stubs are not checked in: they are generated at build time
from the same .proto files the server is built from, so the client can never drift from the API.
``build_py`` runs protoc with ``--python_out`` and ``--grpc_python_out`` into the build tree:
Debian's ``protoc`` with ``grpc_python_plugin`` (protobuf-compiler-grpc) when both are on PATH,
else ``grpc_tools.protoc`` from grpcio-tools. Works offline, into a virtual environment that sees
Debian's grpcio, protobuf, numpy and setuptools (Debian 12's /usr/bin/python3 itself is externally
managed; README.md):

    /usr/bin/python3 -m venv --system-site-packages ~/.venvs/animspace
    ~/.venvs/animspace/bin/python -m pip install --no-build-isolation --no-deps clients/python

The build is out of tree (issue #39): setuptools' ``build/`` and ``*.egg-info`` go under
``$ANIMSPACE_PYTHON_BUILD_DIR`` (default: a folder of the system's temporary directory named after
this checkout), never into the checkout pip installs from.

The .proto files are found, in order, at ``$ANIMSPACE_PROTO_DIR``, ``./proto`` (an sdist: ``sdist``
copies them in) and ``../../proto`` (the repository). ``$PROTOC`` and ``$GRPC_PYTHON_PLUGIN``
override the tools.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
from typing import List, Optional

from setuptools import setup
from setuptools.command.build import build
from setuptools.command.build_py import build_py
from setuptools.command.egg_info import egg_info
from setuptools.command.sdist import sdist

HERE = pathlib.Path(__file__).resolve().parent
API = pathlib.PurePosixPath("animspace/v1")


def out_of_tree() -> pathlib.Path:
    """Where setuptools' intermediate files go: one folder per checkout, outside it."""
    if os.environ.get("ANIMSPACE_PYTHON_BUILD_DIR"):
        return pathlib.Path(os.environ["ANIMSPACE_PYTHON_BUILD_DIR"]).resolve()
    key = hashlib.sha256(str(HERE).encode()).hexdigest()[:12]
    return pathlib.Path(tempfile.gettempdir()) / f"animspace-python-{key}"


class OutOfTreeBuild(build):
    """build with its build_base outside the checkout (a command-line --build-base still wins)."""

    def initialize_options(self) -> None:
        super().initialize_options()
        self.build_base = str(out_of_tree() / "build")


class OutOfTreeEggInfo(egg_info):
    """egg_info writing animspace.egg-info outside the checkout (--egg-base still wins)."""

    def initialize_options(self) -> None:
        super().initialize_options()
        out_of_tree().mkdir(parents=True, exist_ok=True)
        self.egg_base = str(out_of_tree())


def proto_dir() -> pathlib.Path:
    candidates: List[pathlib.Path] = []
    if os.environ.get("ANIMSPACE_PROTO_DIR"):
        candidates.append(pathlib.Path(os.environ["ANIMSPACE_PROTO_DIR"]))
    candidates += [HERE / "proto", HERE.parent.parent / "proto"]
    for candidate in candidates:
        if (candidate / API / "common.proto").is_file():
            return candidate
    raise SystemExit("animspace: cannot find the API's .proto files (animspace/v1/common.proto) in any of "
                     + ", ".join(str(c) for c in candidates) + "; set ANIMSPACE_PROTO_DIR")


def proto_files(root: pathlib.Path) -> List[str]:
    return sorted(str(path.relative_to(root)) for path in (root / API).glob("*.proto"))


def protoc_command(root: pathlib.Path, out: pathlib.Path) -> List[str]:
    """The command generating the messages and stubs of every API .proto under ``out``."""
    arguments = [f"--proto_path={root}", f"--python_out={out}", f"--grpc_python_out={out}"] + proto_files(root)
    protoc: Optional[str] = os.environ.get("PROTOC") or shutil.which("protoc")
    plugin: Optional[str] = os.environ.get("GRPC_PYTHON_PLUGIN") or shutil.which("grpc_python_plugin")
    if protoc and plugin:
        return [protoc, f"--plugin=protoc-gen-grpc_python={plugin}"] + arguments
    # grpcio-tools bundles protoc, the plugin and the well-known types.
    tools = importlib.util.find_spec("grpc_tools")
    if tools is None or tools.origin is None:
        raise SystemExit("animspace: generating animspace.v1 needs protoc with grpc_python_plugin "
                         "(Debian: protobuf-compiler protobuf-compiler-grpc) or grpcio-tools")
    include = pathlib.Path(tools.origin).resolve().parent / "_proto"
    return [sys.executable, "-m", "grpc_tools.protoc", f"--proto_path={include}"] + arguments


class BuildPyWithStubs(build_py):
    """build_py, then protoc: the generated animspace/v1 package lands beside the sources."""

    def run(self) -> None:
        super().run()
        root = proto_dir()
        out = pathlib.Path(self.build_lib).resolve()
        command = protoc_command(root, out)
        self.announce("generating animspace.v1: " + " ".join(command), level=2)
        if self.dry_run:
            return
        (out / API).mkdir(parents=True, exist_ok=True)
        subprocess.run(command, check=True, cwd=root)
        (out / API / "__init__.py").write_text('"""Generated from proto/animspace/v1 at build time."""\n')

    def get_outputs(self, include_bytecode: bool = True) -> List[str]:
        outputs = super().get_outputs(include_bytecode)
        out = pathlib.Path(self.build_lib) / API
        generated = [out / "__init__.py"]
        for proto in proto_files(proto_dir()):
            stem = pathlib.PurePosixPath(proto).stem
            generated += [out / f"{stem}_pb2.py", out / f"{stem}_pb2_grpc.py"]
        return outputs + [str(path) for path in generated]


class SdistWithProtos(sdist):
    """sdist, carrying a copy of the .proto files so that the archive builds on its own."""

    def make_release_tree(self, base_dir: str, files: List[str]) -> None:
        super().make_release_tree(base_dir, files)
        root = proto_dir()
        for proto in proto_files(root):
            target = pathlib.Path(base_dir) / "proto" / proto
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(root / proto, target)


# Packages here rather than in pyproject's [tool.setuptools] (beta in Debian's setuptools 66).
# The package is flat, as CMake copies it into <build>/python/animspace; animspace/v1 comes
# from BuildPyWithStubs.
setup(packages=["animspace"], package_data={"animspace": ["py.typed"]},
      cmdclass={"build": OutOfTreeBuild, "egg_info": OutOfTreeEggInfo, "build_py": BuildPyWithStubs,
                "sdist": SdistWithProtos})

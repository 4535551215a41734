"""The package installs offline with pip, generating its animspace.v1 stubs from proto/ at build time."""
import importlib.util
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]


def _missing_tools():
    if subprocess.run([sys.executable, "-m", "pip", "--version"], capture_output=True).returncode != 0:
        return f"{sys.executable} -m pip is not available"
    if importlib.util.find_spec("grpc_tools") is None:
        if shutil.which("protoc") is None:
            return "protoc is not installed (Debian: protobuf-compiler)"
        if shutil.which("grpc_python_plugin") is None:
            return "grpc_python_plugin is not installed (Debian: protobuf-compiler-grpc)"
    return None


@pytest.mark.skipif(_missing_tools() is not None, reason=str(_missing_tools()))
def test_pip_installs_the_package_with_generated_stubs(tmp_path):
    # A copy of the two folders the build reads, in the repository's layout (clients/python and
    # proto/ two levels up), so that pip's in-tree build leaves no build/ or *.egg-info behind in
    # the working tree.
    source = tmp_path / "src"
    shutil.copytree(REPOSITORY / "clients" / "python", source / "clients" / "python",
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__", "dist"))
    shutil.copytree(REPOSITORY / "proto", source / "proto")
    target = tmp_path / "site"
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    install = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index", "--target",
         str(target), "clients/python"], cwd=source, capture_output=True, text=True, timeout=300, env=environment)
    assert install.returncode == 0, install.stdout + install.stderr

    generated = sorted(p.name for p in (target / "animspace" / "v1").glob("*_pb2*.py"))
    protos = sorted((REPOSITORY / "proto" / "animspace" / "v1").glob("*.proto"))
    assert generated == sorted([f"{p.stem}_pb2.py" for p in protos] + [f"{p.stem}_pb2_grpc.py" for p in protos])
    assert (target / "animspace" / "py.typed").exists()

    check = subprocess.run(
        [sys.executable, "-c",
         "import animspace; from animspace.v1 import poses_pb2, poses_pb2_grpc; "
         "print(animspace.__file__); print(poses_pb2.PoseResult.DESCRIPTOR.full_name); "
         "print(animspace.Client.__name__, animspace.NotFound.__mro__[1].__name__)"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60, env=dict(environment, PYTHONPATH=str(target)))
    assert check.returncode == 0, check.stderr
    file, message, names = check.stdout.split("\n")[:3]
    assert pathlib.Path(file).resolve().is_relative_to(target.resolve())
    assert message == "animspace.v1.PoseResult" and names == "Client RpcError"

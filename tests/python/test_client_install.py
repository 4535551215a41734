"""The package installs offline with pip, generating its animspace.v1 stubs from proto/ at build time."""
import importlib.util
import os
import pathlib
import re
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
    # proto/ two levels up): pip builds in the folder it is given, and the copy shows what that
    # build leaves there (issue #39: nothing; setup.py builds out of tree).
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
    left = sorted(p.name for p in (source / "clients" / "python").iterdir()
                  if p.name == "build" or p.name.endswith(".egg-info"))
    assert left == [], f"pip install wrote {left} into the source folder"

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


def readme_install_commands(readme: pathlib.Path):
    """The shell lines that README tells a user to run to install the package: the fenced ```sh
    block holding its `pip install`, else (a README that gives it inline) every `…pip install…`
    code span. Comments stay, as bash reads them."""
    text = readme.read_text()
    blocks = re.findall(r"^```sh\n(.*?)^```", text, flags=re.S | re.M)
    for block in blocks:
        if "pip install" in block:
            return [line for line in block.splitlines() if line.strip()]
    return re.findall(r"`([^`\n]*pip install[^`\n]*)`", text)


def _interpreter_of(commands):
    """The Python the README's `… -m pip install` line installs into (its first word)."""
    line = next(line for line in commands if "-m pip install" in line)
    return line.split()[0]


def _missing_venv():
    if importlib.util.find_spec("ensurepip") is None:
        return "the venv module cannot install pip (Debian: python3-venv)"
    return _missing_tools()


@pytest.mark.skipif(_missing_venv() is not None, reason=str(_missing_venv()))
@pytest.mark.parametrize("readme", ["README.md", "clients/python/README.md"])
def test_the_readmes_install_commands_work_as_written(readme, daemon, tmp_path):
    # Debian 12 marks /usr/bin/python3 externally managed (PEP 668): pip refuses to install into
    # it, so what a README gives must work there. The lines run as written, with bash, from a copy
    # of the repository's two folders the build reads; HOME is a temporary folder (a README
    # installing under ~ installs there) and pip may not reach an index (PIP_NO_INDEX), as on a
    # machine without network.
    commands = readme_install_commands(REPOSITORY / readme)
    assert commands, f"{readme}: no install command found"
    source = tmp_path / "src"
    shutil.copytree(REPOSITORY / "clients" / "python", source / "clients" / "python",
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__", "dist"))
    shutil.copytree(REPOSITORY / "proto", source / "proto")
    home = tmp_path / "home"
    home.mkdir()
    environment = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PIP_TARGET")}
    environment.update(HOME=str(home), PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
    install = subprocess.run(["bash", "-euo", "pipefail", "-c", "\n".join(commands)], cwd=source,
                             capture_output=True, text=True, timeout=300, env=environment)
    assert install.returncode == 0, "\n".join(commands) + "\n" + install.stdout + install.stderr

    # The interpreter it installed into imports the installed package (not the build tree's) and
    # talks to a daemon.
    python = os.path.expanduser(_interpreter_of(commands).replace("~", str(home), 1))
    check = subprocess.run(
        [python, "-c",
         "import sys, animspace\n"
         "print(animspace.__file__)\n"
         "with animspace.Client(sys.argv[1]) as client:\n"
         "    client.wait_until_serving()\n"
         "    print(client.health(), client.describe_key_points('arm-pmsc').count)\n", daemon],
        cwd=tmp_path, capture_output=True, text=True, timeout=60, env=environment)
    assert check.returncode == 0, check.stderr
    file, answer = check.stdout.splitlines()[:2]
    assert pathlib.Path(file).resolve().is_relative_to(home.resolve())
    assert not pathlib.Path(file).resolve().is_relative_to(source.resolve())
    assert answer.startswith("SERVING ") and int(answer.split()[1]) > 0

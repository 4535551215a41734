"""scripts/check-module-graph.py: passes on the tree as it is, and fails — naming the file, the
line and the rule — on copies of the tree with each kind of violation planted in them."""
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
CHECKER = ROOT / "scripts" / "check-module-graph.py"


def run_checker(root):
    result = subprocess.run(["/usr/bin/python3", str(CHECKER), "--root", str(root)],
                            capture_output=True, text=True, check=False)
    return result.returncode, result.stdout


@pytest.fixture
def tree(tmp_path):
    """A copy of what the checker reads: the document, every tree's sources and build files."""
    copy = tmp_path / "tree"
    ignore = shutil.ignore_patterns("build*", "corpus", "regressions", "*.png", "*.json", "__pycache__")
    for name in ("docs", "core", "server", "clients", "loadtest", "harness", "bench", "fuzz", "tests"):
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, copy / name, ignore=ignore)
    return copy


def test_the_tree_as_it_is_passes():
    code, out = run_checker(ROOT)
    assert code == 0, out


def test_an_upward_include_fails_naming_file_line_and_allowed_modules(tree):
    victim = tree / "core" / "pmsc" / "soft_cache.cpp"
    lines = victim.read_text().splitlines()
    lines.insert(1, '#include "core/model/model_info.h"')
    victim.write_text("\n".join(lines) + "\n")
    code, out = run_checker(tree)
    assert code == 1
    assert "core/pmsc/soft_cache.cpp:2: includes core/model/model_info.h: core/pmsc may include only " \
           "animspace common container geometry" in out, out


def test_a_cycle_in_the_document_fails(tree):
    doc = tree / "docs" / "ARCHITECTURE.md"
    doc.write_text(doc.read_text().replace("\ngeometry: common\n", "\ngeometry: common pmsc\n"))
    code, out = run_checker(tree)
    assert code == 1
    assert "the module graph has a cycle" in out, out
    # The build no longer matches the document either.
    assert "core/geometry/CMakeLists.txt: DEPENDS common, but ARCHITECTURE.md says common pmsc" in out, out


def test_core_including_the_server_or_the_protos_fails(tree):
    victim = tree / "core" / "common" / "result.cpp"
    victim.write_text('#include "server/status_mapping.h"\n#include "animspace/v1/poses.pb.h"\n' + victim.read_text())
    code, out = run_checker(tree)
    assert code == 1
    assert "core/common/result.cpp:1: includes server/status_mapping.h: core/ may include only no other tree" in out
    assert "core/common/result.cpp:2: includes animspace/v1/poses.pb.h" in out, out


def test_a_folder_under_core_that_is_not_a_module_fails(tree):
    (tree / "core" / "stray").mkdir()
    (tree / "core" / "stray" / "thing.cpp").write_text("int x;\n")
    code, out = run_checker(tree)
    assert code == 1
    assert "core/stray: not a module" in out, out


def test_compiling_another_trees_source_fails(tree):
    cmake = tree / "server" / "CMakeLists.txt"
    cmake.write_text(cmake.read_text() + "\nadd_library(x STATIC ${PROJECT_SOURCE_DIR}/core/common/result.cpp)\n")
    code, out = run_checker(tree)
    assert code == 1
    assert "compiles a source file of core/; link its library" in out, out

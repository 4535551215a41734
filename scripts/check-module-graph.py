#!/usr/bin/python3
"""Checks the tree against the module graph written in docs/ARCHITECTURE.md.

docs/ARCHITECTURE.md holds two fenced blocks that this script reads:
  ```modules   one line per core module: `<module>: <modules it may include>`
  ```trees     one line per top-level tree: `<tree>: <trees it may include>`

Fails (exit 1, one line per finding, `file:line: …`) when
  - a core module's CMakeLists (animspace_core_module(<name> DEPENDS …)) lists other
    dependencies than the document, or a folder under core/ is not a module;
  - the module graph has a cycle;
  - a file in core/<m>/ includes a header of a module that <m> does not depend on;
  - a file includes a header of a tree its tree may not include (core never includes server,
    clients or the generated protos; tools do not reach into tests/, …), or a header of the
    command line's private folder clients/cpp/cli/ from outside it;
  - a CMakeLists compiles a source file of another tree instead of linking its library.
Run by every build (a custom target) and by the tests; see docs/ARCHITECTURE.md.
"""
import argparse
import pathlib
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')
MODULE_CALL = re.compile(r"animspace_core_module\(\s*(\w+)(.*?)\)", re.S)
FOREIGN_SOURCE = re.compile(r"\$\{PROJECT_SOURCE_DIR\}/([a-z_]+)/[^\s)]+\.(?:cpp|cc|c)\b")
SOURCE_SUFFIXES = {".h", ".hpp", ".cpp", ".cc", ".c"}
# The generated protos are included as "animspace/v1/…"; that prefix is the tree `proto`.
PROTO_PREFIX = "animspace/v1/"
PRIVATE_CLI = "clients/cpp/cli/"


def read_block(doc: pathlib.Path, name: str) -> dict:
    text = doc.read_text(encoding="utf-8")
    match = re.search(r"^```" + name + r"\n(.*?)^```", text, re.S | re.M)
    if not match:
        sys.exit(f"{doc}: no ```{name} block")
    graph = {}
    for number, line in enumerate(match.group(1).splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        head, _, tail = line.partition(":")
        graph[head.strip()] = set(tail.split())
    return graph


def cycle_in(graph: dict):
    state = {}

    def visit(node, path):
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return path + [node, nxt]
            if nxt not in state:
                found = visit(nxt, path + [node])
                if found:
                    return found
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node, [])
            if found:
                return found[found.index(found[-1]):]
    return None


def tree_of_include(target: str, trees: dict):
    if target.startswith(PROTO_PREFIX):
        return "proto"
    head = target.split("/", 1)[0]
    return head if head in trees else None


def check(root: pathlib.Path) -> list:
    problems = []
    doc = root / "docs" / "ARCHITECTURE.md"
    modules = read_block(doc, "modules")
    trees = read_block(doc, "trees")

    for name, deps in modules.items():
        for dep in sorted(deps - set(modules)):
            problems.append(f"{doc}: module {name} depends on {dep}, which is not a module")
    found = cycle_in(modules)
    if found:
        problems.append(f"{doc}: the module graph has a cycle: {' -> '.join(found)}")

    # The build's graph must be the document's.
    core = root / "core"
    built = {}
    for folder in sorted(p for p in core.iterdir() if p.is_dir()):
        cmake = folder / "CMakeLists.txt"
        calls = MODULE_CALL.findall(cmake.read_text(encoding="utf-8")) if cmake.exists() else []
        if len(calls) != 1 or calls[0][0] != folder.name:
            problems.append(f"{folder}: not a module (expected one animspace_core_module({folder.name} …) "
                            f"in {cmake.name})")
            continue
        args = calls[0][1].split()
        deps = set()
        if "DEPENDS" in args:
            for token in args[args.index("DEPENDS") + 1:]:
                if token.isupper():
                    break
                deps.add(token)
        built[folder.name] = deps
    for name in sorted(set(built) | set(modules)):
        if name not in modules:
            problems.append(f"{doc}: module {name} is built (core/{name}/CMakeLists.txt) but not in the graph")
        elif name not in built:
            problems.append(f"{doc}: module {name} is in the graph but core/{name} does not build it")
        elif built[name] != modules[name]:
            problems.append(f"core/{name}/CMakeLists.txt: DEPENDS {' '.join(sorted(built[name])) or '(none)'}, "
                            f"but {doc.name} says {' '.join(sorted(modules[name])) or '(none)'}")

    # Every #include against the two graphs.
    for tree in sorted(t for t in trees if t != "proto"):
        base = root / tree
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*")):
            if path.suffix not in SOURCE_SUFFIXES or not path.is_file():
                continue
            relative = path.relative_to(root).as_posix()
            module = relative.split("/")[1] if tree == "core" else None
            for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
                match = INCLUDE.match(line)
                if not match:
                    continue
                target = match.group(1)
                where = f"{relative}:{number}: includes {target}"
                target_tree = tree_of_include(target, trees)
                if target_tree is None:
                    continue
                if target_tree != tree and target_tree not in trees[tree]:
                    allowed = " ".join(sorted(trees[tree])) or "no other tree"
                    problems.append(f"{where}: {tree}/ may include only {allowed}")
                    continue
                if target.startswith(PRIVATE_CLI) and not (relative.startswith(PRIVATE_CLI) or tree == "tests"):
                    problems.append(f"{where}: {PRIVATE_CLI} is the command line's own folder; "
                                    "share code through a library with its own folder")
                    continue
                if module and target.startswith("core/"):
                    other = target.split("/")[1]
                    if other != module and other not in modules.get(module, set()):
                        allowed = " ".join(sorted(modules.get(module, ()))) or "no other module"
                        problems.append(f"{where}: core/{module} may include only {allowed} "
                                        f"(docs/ARCHITECTURE.md)")

    # Build files: link another tree's library, do not compile its sources.
    for cmake in sorted(root.rglob("CMakeLists.txt")):
        relative = cmake.relative_to(root).as_posix()
        tree = relative.split("/")[0]
        if tree not in trees or tree == "CMakeLists.txt":
            continue
        for number, line in enumerate(cmake.read_text(encoding="utf-8").splitlines(), 1):
            for other in FOREIGN_SOURCE.findall(line):
                if other != tree:
                    problems.append(f"{relative}:{number}: compiles a source file of {other}/; link its library")
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=pathlib.Path, default=pathlib.Path(__file__).resolve().parent.parent)
    args = parser.parse_args()
    problems = check(args.root.resolve())
    for problem in problems:
        print(problem)
    if problems:
        print(f"module graph: {len(problems)} problem(s); the graph is in docs/ARCHITECTURE.md")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Builds the Blender add-on's installable zip: the add-on package plus the Python client.

The zip holds one top-level folder, ``animspace_blender/`` (what Blender's "Install from file"
expects), with the project's ``animspace`` package and its generated ``animspace.v1`` stubs
copied into ``animspace_blender/vendor/`` — see ``animspace_blender/__init__.py`` for why the
client travels inside the add-on. Entries are sorted and dated 1980-01-01, so the same sources
give the same bytes.

Usage: build_addon.py --addon DIR --python BUILD/python --output ZIP
"""
import argparse
import pathlib
import sys
import zipfile

FIXED_DATE = (1980, 1, 1, 0, 0, 0)
WANTED = {".py", ".typed"}  # sources and PEP 561's marker; no __pycache__, no editor leftovers


def files_under(root: pathlib.Path):
    return sorted(p for p in root.rglob("*") if p.is_file() and p.suffix in WANTED and "__pycache__" not in p.parts)


def add(archive: zipfile.ZipFile, source: pathlib.Path, name: str) -> None:
    info = zipfile.ZipInfo(name, FIXED_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    archive.writestr(info, source.read_bytes())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--addon", type=pathlib.Path, required=True, help="clients/blender/animspace_blender")
    parser.add_argument("--python", type=pathlib.Path, required=True, help="the build's python folder")
    parser.add_argument("--output", type=pathlib.Path, required=True, help="the zip to write")
    args = parser.parse_args()

    client = args.python / "animspace"
    for needed in (args.addon / "__init__.py", client / "__init__.py", client / "v1" / "poses_pb2.py"):
        if not needed.is_file():
            print(f"build_addon.py: {needed} is missing (build the Python client first)", file=sys.stderr)
            return 1
    args.output.parent.mkdir(parents=True, exist_ok=True)
    partial = args.output.with_name(args.output.name + ".partial")
    with zipfile.ZipFile(partial, "w") as archive:
        for source in files_under(args.addon):
            add(archive, source, "animspace_blender/" + source.relative_to(args.addon).as_posix())
        for source in files_under(client):
            add(archive, source, "animspace_blender/vendor/animspace/" + source.relative_to(client).as_posix())
    partial.replace(args.output)  # a failed build never leaves a half-written zip under the real name
    return 0


if __name__ == "__main__":
    sys.exit(main())

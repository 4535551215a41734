#!/usr/bin/python3
"""Fetch a level of detail of an animation-space model and write it as a Wavefront OBJ.

The level is chosen like a render-farm node would (Merry 2007 §7.3): the coarsest whose error ε^l
projects under a pixel tolerance at a camera distance (eq. 7.2), the finest under a vertex
budget, or a level by index. The mesh is posed at the rest pose, or at a skeleton pose given as a
.npy file of B×3×4 (or B×4×4) bone transforms.

    lod_to_obj.py arm-animspace -o arm.obj --tolerance-px 1.5 --distance 40
    lod_to_obj.py arm-animspace -o arm-300.obj --max-vertices 300
    lod_to_obj.py arm-animspace -o arm-l3.obj --level 3
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Optional

import numpy as np

import animspace


def read_token(path: Optional[str]) -> Optional[str]:
    if path:
        with open(path) as file:
            return file.read().strip()
    return os.environ.get("ANIMSPACE_TOKEN") or None


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="an animation-space model (or a PMSC model carrying one), e.g. arm-animspace")
    parser.add_argument("-o", "--output", required=True, help="the OBJ file to write")
    parser.add_argument("--server", default="127.0.0.1:50051", help="animspaced address (default %(default)s)")
    parser.add_argument("--version", type=int, default=0, help="model version (0: the default one)")
    parser.add_argument("--token-file", help="bearer token file (default: $ANIMSPACE_TOKEN)")
    choice = parser.add_mutually_exclusive_group(required=True)
    choice.add_argument("--level", type=int, help="a level by index, 0 = full detail")
    choice.add_argument("--max-vertices", type=int, help="the finest level with at most this many vertices")
    choice.add_argument("--tolerance-px", type=float, help="screen-space error, pixels (with --distance)")
    parser.add_argument("--distance", type=float, help="camera to the model's bounding-sphere centre, model units")
    parser.add_argument("--viewport-width", type=int, default=1920, help="viewport width, pixels (default 1920)")
    parser.add_argument("--fov-deg", "--fov", dest="fov", type=float, default=45.0,
                        help="horizontal field of view in DEGREES (default 45; the API's horizontal_fov_rad is "
                             "radians, converted here), as the animspace command line's --fov-deg")
    parser.add_argument("--pose", help=".npy of B×3×4 or B×4×4 bone transforms (default: the rest pose)")
    parser.add_argument("--local", action="store_true", help="--pose holds joint transforms L_j, not G_j")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = parser.parse_args(argv)
    if (args.tolerance_px is None) != (args.distance is None):
        parser.error("--tolerance-px and --distance go together")

    pose = np.load(args.pose) if args.pose else None
    with animspace.Client(args.server, token=read_token(args.token_file)) as client:
        mesh = client.get_lod(args.model, version=args.version, level=args.level, max_vertices=args.max_vertices,
                              tolerance_px=args.tolerance_px, distance=args.distance,
                              viewport_width_px=args.viewport_width, horizontal_fov_rad=math.radians(args.fov),
                              form="posed", pose=pose, space="local" if args.local else "global")
    h = mesh.header
    mesh.save(args.output)  # OBJ, posed at the pose asked for (the server posed FORM_POSED)
    report = {"model": args.model, "version": h.model_version, "level": h.level, "level_count": h.level_count,
              "epsilon": h.epsilon, "tolerated_error": h.tolerated_error, "vertices": h.vertex_count,
              "faces": h.face_count, "chunks": mesh.chunk_count, "bytes": mesh.bytes_received, "output": args.output}
    if args.json:
        print(json.dumps(report))
    else:
        print(f"{args.model} v{h.model_version}: level {h.level} of {h.level_count} (ε^l {h.epsilon:.6g}), "
              f"{h.vertex_count} vertices, {h.face_count} faces → {args.output}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (animspace.Error, ValueError, OSError) as error:
        print(f"lod_to_obj: {error}", file=sys.stderr)
        sys.exit(1)

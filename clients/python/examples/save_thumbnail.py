#!/usr/bin/python3
"""Render a model's thumbnail on the server (headless EGL) and save it as PNG.

Draws the rest pose, or a frame of the model's stored sequence (--frame), optionally with a
wireframe overlay and at the coarsest level of detail whose error stays under --tolerance-px
pixels (Merry 2007 eq. 7.2).

    save_thumbnail.py arm-animspace -o arm.png --width 512 --height 256 --wireframe
    save_thumbnail.py arm -o arm-30.png --frame 30
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Optional

import animspace


def read_token(path: Optional[str]) -> Optional[str]:
    if path:
        with open(path) as file:
            return file.read().strip()
    return os.environ.get("ANIMSPACE_TOKEN") or None


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="any model, e.g. arm-animspace")
    parser.add_argument("-o", "--output", required=True, help="the PNG file to write")
    parser.add_argument("--server", default="127.0.0.1:50051", help="animspaced address (default %(default)s)")
    parser.add_argument("--version", type=int, default=0, help="model version (0: the default one)")
    parser.add_argument("--token-file", help="bearer token file (default: $ANIMSPACE_TOKEN)")
    parser.add_argument("--width", type=int, default=256, help="pixels (default 256)")
    parser.add_argument("--height", type=int, default=256, help="pixels (default 256)")
    parser.add_argument("--frame", type=int, help="a frame of the model's stored sequence, zero-based")
    parser.add_argument("--wireframe", action="store_true", help="overlay the triangle edges")
    parser.add_argument("--tolerance-px", type=float, default=0.0, help="LOD error allowed, pixels (0: full detail)")
    parser.add_argument("--shading", choices=["blinn_phong", "lambert"], help="default: the server's (Blinn-Phong)")
    parser.add_argument("--deadline-s", "--timeout", dest="deadline_s", type=float, default=60.0,
                        help="deadline, seconds (a render queues behind others; --timeout: the old name)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = parser.parse_args(argv)

    with animspace.Client(args.server, token=read_token(args.token_file)) as client:
        thumbnail = client.render_thumbnail(args.model, args.width, args.height, version=args.version,
                                            sequence_frame=args.frame, show_wireframe=args.wireframe,
                                            tolerance_px=args.tolerance_px, shading=args.shading,
                                            deadline_s=args.deadline_s)
    thumbnail.save(args.output)
    report = {"model": args.model, "version": thumbnail.model_version, "width_px": thumbnail.width_px,
              "height_px": thumbnail.height_px, "lod_level": thumbnail.lod_level, "render_ms": thumbnail.render_ms,
              "bytes": len(thumbnail.png), "output": args.output}
    if args.json:
        print(json.dumps(report))
    else:
        print(f"{args.model} v{thumbnail.model_version}: {thumbnail.width_px}×{thumbnail.height_px}, level "
              f"{thumbnail.lod_level}, {thumbnail.render_ms:.1f} ms → {args.output} ({len(thumbnail.png)} bytes)")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (animspace.Error, ValueError, OSError) as error:
        print(f"save_thumbnail: {error}", file=sys.stderr)
        sys.exit(1)

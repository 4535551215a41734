#!/usr/bin/python3
"""Replay a PC2 point cache through a PMSC model's soft cache and report hit / blend / miss rates.

Each frame's key points (the indices DescribeKeyPoints names) are streamed over one
StreamKeyPoints call; the server answers every frame with HIT (e_key ≤ ε_min), BLEND or MISS
(e_key ≥ ε_max) — Meyer & Anderson 2006 §5. This is how a studio checks whether a soft cache
trained on yesterday's animation still covers today's shots before trusting it on the farm.

    replay_pc2.py frames.pc2 --model arm-pmsc [--select 1::2] [--json] [--server 127.0.0.1:50051]

The cache must hold the model's full point set (for cross-PMSC, its control point set) in the
model's object frame and units.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Iterator, Optional

import numpy as np

import animspace


def parse_slice(text: str) -> slice:
    """Python slice syntax over frames: "::2" (even frames), "1::2", "10:20", "5"."""
    parts = text.split(":")
    if len(parts) > 3 or not all(p.strip().lstrip("-").isdigit() or p.strip() == "" for p in parts):
        raise argparse.ArgumentTypeError(f"expected START:STOP:STEP, got {text!r}")
    numbers = [int(p) if p.strip() else None for p in parts]
    if len(numbers) == 1:
        assert numbers[0] is not None
        return slice(numbers[0], numbers[0] + 1 if numbers[0] != -1 else None)
    if len(numbers) == 3 and numbers[2] == 0:
        raise argparse.ArgumentTypeError("the step must not be 0")
    return slice(*numbers)


def read_token(path: Optional[str]) -> Optional[str]:
    if path:
        with open(path) as file:
            return file.read().strip()
    return os.environ.get("ANIMSPACE_TOKEN") or None


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pc2", help="the point cache (POINTCACHE2, version 1)")
    parser.add_argument("--model", required=True, help="a PMSC model, e.g. arm-pmsc")
    parser.add_argument("--version", type=int, default=0, help="model version (0: the default one)")
    parser.add_argument("--server", default="127.0.0.1:50051", help="animspaced address (default %(default)s)")
    parser.add_argument("--token-file", help="bearer token file (default: $ANIMSPACE_TOKEN)")
    parser.add_argument("--select", type=parse_slice, default=slice(None), help="frames, as a Python slice: 1::2")
    parser.add_argument("--deadline-s", "--timeout", dest="deadline_s", type=float, default=600.0,
                        help="deadline of the whole stream, seconds (default 600; --timeout: the old name)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("-v", "--verbose", action="store_true", help="one line per frame")
    args = parser.parse_args(argv)

    cache = animspace.read_pc2(args.pc2)
    frame_numbers = np.arange(cache.frame_count)[args.select]
    with animspace.Client(args.server, token=read_token(args.token_file)) as client:
        keys = client.describe_key_points(args.model, args.version)
        if cache.point_count != keys.control_point_count:
            print(f"replay_pc2: {args.pc2} has {cache.point_count} points per frame, {args.model} v"
                  f"{keys.model_version} expects {keys.control_point_count}", file=sys.stderr)
            return 2

        def poses() -> Iterator[animspace.KeyPointPose]:
            # Lazy: one frame's K key points and C check points at a time, however long the cache.
            for f in frame_numbers:
                yield keys.pose(cache.frames[f])

        counts = {"HIT": 0, "BLEND": 0, "MISS": 0}
        errors = []
        needed = 0
        # Pin the version the key indices belong to; only the verdicts are needed here.
        for f, result in zip(frame_numbers, client.stream_key_points(
                args.model, poses(), version=keys.model_version, omit_points=True, deadline_s=args.deadline_s)):
            counts[result.status] = counts.get(result.status, 0) + 1
            errors.append(result.key_point_error)
            needed += result.full_evaluation_needed
            if args.verbose and not args.json:
                check = f" e_check {result.check_point_error:.6g}" if result.checked else ""
                print(f"frame {f}: {result.status} e_key {result.key_point_error:.6g}{check} "
                      f"α {result.blend_weight:.3f}")

    frames = len(errors)
    rate = {status: (count / frames if frames else 0.0) for status, count in counts.items()}
    report = {
        "model": args.model,
        "version": keys.model_version,
        "pc2": args.pc2,
        "frames": frames,
        "key_points": keys.count,
        "hit": counts["HIT"],
        "blend": counts["BLEND"],
        "miss": counts["MISS"],
        "hit_rate": rate["HIT"],
        "blend_rate": rate["BLEND"],
        "miss_rate": rate["MISS"],
        "full_evaluation_needed": needed,
        "mean_key_point_error": float(np.mean(errors)) if errors else 0.0,
        "max_key_point_error": float(np.max(errors)) if errors else 0.0,
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(f"{args.model} v{keys.model_version}: {frames} frames, {keys.count} key points")
        for status in ("HIT", "BLEND", "MISS"):
            print(f"  {status.lower():5} {counts[status]:6d}  {100 * rate[status]:6.2f} %")
        print(f"  e_key mean {report['mean_key_point_error']:.6g}, max {report['max_key_point_error']:.6g}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (animspace.Error, ValueError, OSError) as error:
        print(f"replay_pc2: {error}", file=sys.stderr)
        sys.exit(1)

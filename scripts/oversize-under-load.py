#!/usr/bin/python3
"""Oversized requests against a daemon under legitimate load: what --grpc-memory-bytes buys.

Starts build/bin/animspaced on the demo repository with --max-message-bytes 4 MiB, then for
`--seconds` runs 4 legitimate callers (EvaluateKeyPoints, 64 poses of arm-pmsc) beside
`--attackers` callers that send `--request-mib` MiB requests in a loop, and prints the daemon's
peak RSS and every outcome. Run it once per --grpc-memory-bytes value to compare (0 = unbounded).
docs/RELIABILITY.md records a run. Needs `make build`; run from the repository root.
"""
import argparse
import collections
import os
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "build", "python"))

import grpc  # noqa: E402
import numpy as np  # noqa: E402

import animspace  # noqa: E402
from animspace.v1 import poses_pb2, poses_pb2_grpc  # noqa: E402


def memory_mib(pid: int) -> dict:
    out = {}
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            key, value = line.split(":", 1)
            if key in ("VmHWM", "VmRSS"):
                out[key] = int(value.split()[0]) / 1024
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grpc-memory-bytes", type=int, required=True)
    parser.add_argument("--attackers", type=int, default=3)
    parser.add_argument("--request-mib", type=int, default=128)
    parser.add_argument("--seconds", type=float, default=15)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as work:
        port_file = os.path.join(work, "port")
        daemon = subprocess.Popen([os.path.join(ROOT, "build", "bin", "animspaced"), "--listen", "127.0.0.1:0",
                                   "--port-file", port_file, "--max-message-bytes", str(4 << 20),
                                   "--grpc-memory-bytes", str(args.grpc_memory_bytes), "--renderer", "none",
                                   "--log-level", "error"])
        try:
            while not os.path.exists(port_file):
                if daemon.poll() is not None:
                    sys.exit("animspaced exited")
                time.sleep(0.05)
            address = "127.0.0.1:" + open(port_file).read().strip()
            with animspace.Client(address) as client:
                client.wait_until_serving()
                keys = client.describe_key_points("arm-pmsc")
            outcomes: collections.Counter = collections.Counter()
            lock = threading.Lock()
            stop = time.time() + args.seconds

            def count(what: str) -> None:
                with lock:
                    outcomes[what] += 1

            def legitimate() -> None:
                values = np.zeros((64, keys.count, keys.channel_count), np.float32)
                with animspace.Client(address) as caller:
                    while time.time() < stop:
                        try:
                            caller.evaluate_key_points("arm-pmsc", values, timeout=30)
                            count("legitimate OK")
                        except animspace.Error as e:
                            count(f"legitimate {e.code.name}")

            request = poses_pb2.EvaluateKeyPointsRequest()
            request.model.name = "arm-pmsc"
            request.poses.add().key_values.data = bytes(args.request_mib << 20)

            def attack() -> None:
                channel = grpc.insecure_channel(address, options=[("grpc.max_send_message_length", -1)])
                stub = poses_pb2_grpc.PoseServiceStub(channel)
                while time.time() < stop:
                    try:
                        stub.EvaluateKeyPoints(request, timeout=60)
                        count("oversized OK")
                    except grpc.RpcError as e:
                        count(f"oversized {e.code().name}")

            before = memory_mib(daemon.pid)
            threads = [threading.Thread(target=legitimate) for _ in range(4)]
            threads += [threading.Thread(target=attack) for _ in range(args.attackers)]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
            after = memory_mib(daemon.pid)
            print(f"--grpc-memory-bytes {args.grpc_memory_bytes}: {args.attackers} × {args.request_mib} MiB "
                  f"requests for {args.seconds:.0f} s; peak RSS {before['VmHWM']:.0f} -> {after['VmHWM']:.0f} MiB "
                  f"(+{after['VmHWM'] - before['VmHWM']:.0f}); " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
        finally:
            daemon.terminate()
            daemon.wait()


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Plots an animspace-loadtest JSON report: latency percentiles against throughput, one point per
step (the usual load-test curve: where p99 turns up is the knee), and the soft cache's hit, blend
and miss rates over time (per second of the run). Needs Debian's python3-matplotlib.

    /usr/bin/python3 animspace-loadtest-plot.py report.json plot.png
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")  # headless: no display on render-farm nodes or CI
import matplotlib.pyplot as plt  # noqa: E402


def main(report_path: str, png_path: str) -> None:
    with open(report_path) as f:
        report = json.load(f)
    steps = report["steps"]
    figure, (latency, rates) = plt.subplots(1, 2, figsize=(12, 4.5))

    throughput = [s["rps"] for s in steps]
    for key, label in (("p50_us", "p50"), ("p90_us", "p90"), ("p99_us", "p99"), ("p99_9_us", "p99.9")):
        latency.plot(throughput, [s[key] / 1e3 for s in steps], marker="o", label=label)
    for s, x in zip(steps, throughput):
        latency.annotate(s["label"], (x, s["p99_us"] / 1e3), fontsize=7, textcoords="offset points", xytext=(3, 3))
    latency.set_xlabel("throughput (requests/s)")
    latency.set_ylabel("latency (ms)")
    latency.set_yscale("log")
    latency.set_title(f"{report['model']} ({report['rpc']}, batch {report['batch']}) on {len(report['servers'])} server(s)")
    latency.grid(True, which="both", alpha=0.3)
    latency.legend()

    times, hit, blend, miss = [], [], [], []
    for s in steps:
        for second in s["timeline"]:
            poses = second["poses"]
            if poses == 0:
                continue
            times.append(second["t_s"])
            hit.append(second["hits"] / poses)
            blend.append(second["blends"] / poses)
            miss.append(second["misses"] / poses)
    rates.plot(times, hit, label="hit", color="tab:green")
    rates.plot(times, blend, label="blend", color="tab:orange")
    rates.plot(times, miss, label="miss", color="tab:red")
    for s in steps[1:]:
        rates.axvline(s["start_s"], color="grey", alpha=0.3)
    rates.set_xlabel("time (s)")
    rates.set_ylabel("fraction of poses")
    rates.set_ylim(-0.02, 1.02)
    rates.set_title("soft cache verdicts over time")
    rates.grid(True, alpha=0.3)
    rates.legend()

    figure.tight_layout()
    figure.savefig(png_path, dpi=110)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: animspace-loadtest-plot.py REPORT.json PLOT.png")
    main(sys.argv[1], sys.argv[2])

#!/usr/bin/python3
"""Plot animspace-bench lod results: RMS error across poses against the fraction of vertices kept,
one curve per method, one panel per dataset.

    /usr/bin/python3 scripts/plot_lod.py docs/results/bench-lod.json docs/lod-error.png
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(source: str, target: str) -> None:
    with open(source, encoding="utf-8") as f:
        rows = json.load(f)["results"]
    datasets = sorted({r["dataset"] for r in rows})
    figure, axes = plt.subplots(1, len(datasets), figsize=(6 * len(datasets), 4.5), squeeze=False)
    for axis, dataset in zip(axes[0], datasets):
        methods = sorted({r["method"] for r in rows if r["dataset"] == dataset})
        for method in methods:
            points = sorted((r["vertices"], r["rms_error_over_diag"]) for r in rows
                            if r["dataset"] == dataset and r["method"] == method)
            total = max(r["vertices"] / r["target_fraction"] for r in rows if r["dataset"] == dataset)
            axis.plot([v / total for v, _ in points], [e for _, e in points], marker="o", label=method)
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel("fraction of vertices kept")
        axis.set_ylabel("RMS distance to the posed surface / diagonal")
        axis.set_title(f"{dataset}: error across poses")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(target, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

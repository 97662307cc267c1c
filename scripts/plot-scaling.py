#!/usr/bin/python3
"""Plots the cost of each detector against the frame's pixels from Google Benchmark's JSON of the
`scaling/` benchmarks (bench/bench_scaling.cpp): docs/figures/scaling.png, time per frame and
time per megapixel against megapixels on log axes, and a markdown table on stdout with the
exponent k of cost ~ pixels^k between each pair of neighbouring sizes (1: linear).

  build/default/bench/laserline_bench --benchmark_filter='^scaling/' \\
      --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \\
      --benchmark_out=scaling.json --benchmark_out_format=json
  scripts/plot-scaling.py scaling.json [--out docs/figures/scaling.png] [--time real|cpu]

With repetitions the medians are used. Needs python3-matplotlib.
"""
import argparse
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ORDER = ["maxvalue", "fir", "background", "backprojection"]
TO_MS = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}


def read(path, which):
    """{detector: {(width, height): ms per frame}} from the JSON, medians where repeated."""
    with open(path) as f:
        report = json.load(f)
    runs = {}
    for b in report.get("benchmarks", []):
        name = b.get("run_name", b["name"])
        if not name.startswith("scaling/"):
            continue
        if b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median":
            continue
        _, detector, size = name.split("/")[:3]
        width, height = (int(v) for v in size.split("x"))
        runs.setdefault(detector, {})[(width, height)] = b[which + "_time"] * TO_MS[b["time_unit"]]
    if not runs:
        sys.exit("plot-scaling: %s holds no scaling/ benchmark (run with "
                 "--benchmark_filter='^scaling/')" % path)
    return report.get("context", {}), runs


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("json")
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "figures", "scaling.png"))
    parser.add_argument("--time", choices=["real", "cpu"], default="cpu")
    args = parser.parse_args()
    context, runs = read(args.json, args.time)
    detectors = [d for d in ORDER if d in runs] + sorted(d for d in runs if d not in ORDER)

    fig, (per_frame, per_mp) = plt.subplots(1, 2, figsize=(11, 4.4))
    for detector in detectors:
        sizes = sorted(runs[detector], key=lambda s: s[0] * s[1])
        mp = [w * h / 1e6 for w, h in sizes]
        ms = [runs[detector][s] for s in sizes]
        per_frame.plot(mp, ms, "o-", label=detector)
        per_mp.plot(mp, [t / m for t, m in zip(ms, mp)], "o-", label=detector)
    all_mp = sorted({w * h / 1e6 for d in detectors for w, h in runs[d]})
    first = min(runs[d][s] for d in detectors for s in runs[d] if s[0] * s[1] / 1e6 == all_mp[0])
    per_frame.plot([all_mp[0], all_mp[-1]], [first, first * all_mp[-1] / all_mp[0]], "k:",
                   linewidth=1, label="linear in pixels")
    for axes, title, unit in ((per_frame, "time per frame", "ms"),
                              (per_mp, "time per megapixel", "ms / Mpixel")):
        axes.set_xscale("log")
        axes.set_yscale("log")
        axes.set_xlabel("frame size (Mpixel)")
        axes.set_ylabel(unit)
        axes.set_title(title)
        axes.set_xticks(all_mp)
        axes.set_xticklabels(["%dx%d\n%.2g" % (w, h, w * h / 1e6) for w, h in
                              sorted({s for d in detectors for s in runs[d]},
                                     key=lambda s: s[0] * s[1])], fontsize=8)
        axes.minorticks_off()
        axes.yaxis.set_major_locator(LogLocator(subs=(1, 2, 5)))
        axes.yaxis.set_major_formatter(FuncFormatter(lambda v, _: "%g" % v))
        axes.grid(True, which="major", alpha=0.3)
    per_frame.legend(fontsize=8)
    fig.suptitle("laserline detectors, one thread, %s time (%s, %s)"
                 % (args.time.upper() if args.time == "cpu" else "wall",
                    context.get("date", "")[:10], context.get("host_name", "")), fontsize=10)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    fig.savefig(args.out, dpi=100)

    sizes = sorted({s for d in detectors for s in runs[d]}, key=lambda s: s[0] * s[1])
    print("| detector | " + " | ".join("%dx%d" % s for s in sizes) +
          " | ms / Mpixel, smallest to largest | exponent k between sizes (cost ~ pixels^k) |")
    print("| --- " * (len(sizes) + 3) + "|")
    for d in detectors:
        ms = [runs[d].get(s) for s in sizes]
        mp = [w * h / 1e6 for w, h in sizes]
        cells = ["%.3g ms" % t if t is not None else "" for t in ms]
        per = "%.3g to %.3g" % (ms[0] / mp[0], ms[-1] / mp[-1]) if None not in ms else ""
        k = ", ".join("%.2f" % (math.log(ms[i + 1] / ms[i]) / math.log(mp[i + 1] / mp[i]))
                      for i in range(len(sizes) - 1) if ms[i] and ms[i + 1])
        print("| %s | %s | %s | %s |" % (d, " | ".join(cells), per, k))
    print("\nwritten: %s" % os.path.relpath(args.out, os.getcwd()), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""PNG plots of an engine_bench run: analogues of the paper's Fig. 6 and Fig. 7, and the memory-case scaling.

    bench/plot.py [RESULTS.json ...]   (default: bench/results/engine_bench*.json, rows merged)

Writes next to the first JSON file:
  fig7_segment_length.png  time vs segment length (10, 20, 40, none) per input, stencil and mode (paper Fig. 7);
  fig6_segment_times.png   compute time per distance range of the l_seg = 20 rows at the largest resolution
                           (paper Fig. 6: time spent on distances < 20, 20-40, ...);
  memory_scaling.png       time vs voxels within the limit for the sphere-band memory case.
Needs Debian's python3-matplotlib (use /usr/bin/python3).
"""
import glob
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def ok(row):
    return "error" not in row and row.get("time_s") is not None


def main() -> int:

    paths = sys.argv[1:] or sorted(glob.glob(os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                                                          "engine_bench*.json")))
    if not paths:
        print("no results given or found", file=sys.stderr)
        return 2
    rows = []
    for path in paths:
        try:
            with open(path) as f:
                rows += [r for r in json.load(f)["rows"] if ok(r)]
        except (OSError, ValueError, KeyError) as err:
            print(f"cannot read {path}: {err}", file=sys.stderr)
            return 2
    path = paths[0]
    out_dir = os.path.dirname(os.path.abspath(path))

    # Fig. 7: time vs l_seg, "none" plotted at the right end.
    fig7 = [r for r in rows if "fig7" in r.get("groups", [])]
    if fig7:
        order = [10, 20, 40, None]
        labels = ["10", "20", "40", "none"]
        fig, ax = plt.subplots(figsize=(9.5, 4.5))
        series = {}
        for r in fig7:
            series.setdefault((r["case"], r["resolution"], r["stencil"], r["mode"]), {})[r["segment"]] = r["time_s"]
        for (case, res, stencil, mode), pts in sorted(series.items()):
            xs = [i for i, s in enumerate(order) if s in pts]
            ax.plot(xs, [pts[order[i]] for i in xs], marker="o", label=f"{case} {res}³ {stencil} {mode}")
        ax.set_xticks(range(len(order)), labels)
        ax.set_yscale("log")
        ax.set_xlabel("segment length l_seg (voxels)")
        ax.set_ylabel("time (s)")
        ax.set_title("Fig. 7 analogue: time vs segment length")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        fig.tight_layout()
        fig.savefig(os.path.join(out_dir, "fig7_segment_length.png"), dpi=120)
        plt.close(fig)

    # Fig. 6: per-segment compute time of l_seg = 20 rows at the largest resolution.
    seg20 = [r for r in rows if r.get("segment") == 20 and r.get("segments")]
    if seg20:
        top = max(r["resolution"] for r in seg20)
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for r in seg20:
            if r["resolution"] != top or r["stencil"] not in ("fcc12", "cubic26"):
                continue
            segs = r["segments"]
            ax.plot([s["upper"] for s in segs], [s["seconds"] for s in segs], marker=".",
                    label=f"{r['case']} {r['stencil']} {r['mode']}")
        ax.set_xlabel("distance range upper bound (voxels), l_seg = 20")
        ax.set_ylabel("compute time of the segment (s)")
        ax.set_title(f"Fig. 6 analogue: time per distance range, {top}³")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(out_dir, "fig6_segment_times.png"), dpi=120)
        plt.close(fig)

    # Memory case scaling.
    mem = [r for r in rows if r["case"] == "sphere_band" and r.get("voxels_within_limit")]
    if mem:
        fig, ax = plt.subplots(figsize=(6, 4.5))
        for mode in sorted({r["mode"] for r in mem}):
            pts = sorted((r["voxels_within_limit"], r["time_s"], r["resolution"]) for r in mem if r["mode"] == mode)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=mode)
            for v, t, res in pts:
                ax.annotate(f"{res}³", (v, t), fontsize=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("voxels within the limit")
        ax.set_ylabel("time (s)")
        ax.set_title("Sphere band, limit 5 voxels: time vs voxels")
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out_dir, "memory_scaling.png"), dpi=120)
        plt.close(fig)
    print(f"plots written to {out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""ncu_kernels.py CSV [N]: the per-kernel table of an `ncu --csv --page raw` report of cuda.

One row per kernel name: launches, device time in all and per step, and the mean of every other metric the
report holds, weighted by each launch's time. A step ends with its one commit_kernel launch: where the report
holds two or more, only the whole steps between the first and the last count (a window of launches cut
inside a step would count that step's kernels before the cut against the steps around it). ncu runs
each kernel alone, so the sum is device time without the gaps between launches: set beside the step
loop's own time per step, the difference is what launching costs. DRAM bytes (dram__bytes_read.sum,
dram__bytes_write.sum) are summed instead, per step, and with N (the disks) per particle-step; then, with N,
one comment line a whole step: its bytes a particle-step and those of each kernel that moves more than 2 (a
gathering step moves about half again as much as the others)."""
import csv
import sys

# the metrics shown beside the time (ncu's raw page holds every attribute of the device too)
SHOWN = ("sm__throughput.avg.pct_of_peak_sustained_elapsed",
         "gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed", "l1tex__t_sector_hit_rate.pct",
         "lts__t_sector_hit_rate.pct", "sm__warps_active.avg.pct_of_peak_sustained_active", "launch__grid_size")
SUMMED = ("dram__bytes_read.sum", "dram__bytes_write.sum")  # bytes: added up, not averaged


def main():
    path = sys.argv[1]
    disks = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r]
    head = next(i for i, r in enumerate(rows) if "Kernel Name" in r)
    names, units, data = rows[head], rows[head + 1], rows[head + 2:]
    col = {n: i for i, n in enumerate(names)}
    kernel = [r[col["Kernel Name"]].split("(")[0].split("<")[0].replace("void ", "") for r in data]
    ends = [i for i, name in enumerate(kernel) if name == "commit_kernel"]
    if len(ends) >= 2:
        data, kernel = data[ends[0] + 1:ends[-1] + 1], kernel[ends[0] + 1:ends[-1] + 1]
    metrics = [n for n in names if n in SHOWN]
    summed = [n for n in names if n in SUMMED]
    byte_scale = {"byte": 1, "Kbyte": 1e3, "Mbyte": 1e6, "Gbyte": 1e9}
    t = col["gpu__time_duration.sum"]
    scale = {"ns": 1e-3, "usecond": 1, "us": 1, "msecond": 1e3, "ms": 1e3, "nsecond": 1e-3}.get(units[t], 1)
    agg = {}
    each, step = [], []  # each whole step's kernels: (name, bytes)
    for r, name in zip(data, kernel):
        us = float(r[t].replace(",", "")) * scale
        b = {m: float(r[col[m]].replace(",", "")) * byte_scale.get(units[col[m]], 1) for m in summed}
        step.append((name, sum(b.values())))
        if name == "commit_kernel":
            each.append(step)
            step = []
        a = agg.setdefault(name, {"n": 0, "us": 0.0, "m": {m: 0.0 for m in metrics}, "b": {m: 0.0 for m in summed}})
        a["n"] += 1
        a["us"] += us
        for m in summed:
            a["b"][m] += b[m]
        for m in metrics:
            try:
                a["m"][m] += float(r[col[m]].replace(",", "")) * us
            except ValueError:
                pass
    steps = float(agg["commit_kernel"]["n"]) if "commit_kernel" in agg else 1.0
    total = sum(a["us"] for a in agg.values())
    short = [m.split(".")[0].replace("__", ":") + ("_%" if "pct" in m else "") for m in metrics]
    per = "particle_step" if disks else "step"
    byte_cols = "".join(",%s_bytes_per_%s" % (m.split("__")[1].split(".")[0], per) for m in summed)
    print("kernel,launches,us_total,us_per_step,share" + "".join("," + m for m in short) + byte_cols)
    div = steps * (disks if disks else 1.0)
    for name, a in sorted(agg.items(), key=lambda x: -x[1]["us"]):
        vals = "".join("," + ("%.1f" % (a["m"][m] / a["us"]) if a["us"] else "") for m in metrics)
        bytes_ = "".join(",%.1f" % (a["b"][m] / div) for m in summed)
        print("%s,%d,%.1f,%.2f,%.1f%%%s%s" % (name, a["n"], a["us"], a["us"] / steps, 100 * a["us"] / total, vals,
                                            bytes_))
    totals = "".join(",%.1f" % (sum(a["b"][m] for a in agg.values()) / div) for m in summed)
    print("all,%d,%.1f,%.2f,100%%%s%s" % (sum(a["n"] for a in agg.values()), total, total / steps,
                                        "," * len(metrics), totals))
    if disks and summed and len(ends) >= 2:
        for i, st in enumerate(each):
            big = " ".join("%s %.0f" % (n.replace("_kernel", ""), b / disks) for n, b in st if b / disks > 2)
            total_bytes = sum(b for _, b in st) / disks
            print("# step %d of the window: %.0f bytes a particle-step (%s)" % (i + 1, total_bytes, big))


if __name__ == "__main__":
    main()

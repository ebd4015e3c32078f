#!/usr/bin/env python3
"""ncu_kernels.py CSV [N]: the per-kernel table of an `ncu --csv --page raw` report of cuda.

One row per kernel name: launches, device time in all and per step (the steps counted by their one
commit_kernel launch each), and the mean of every other metric the report holds, weighted by each launch's time. ncu runs
each kernel alone, so the sum is device time without the gaps between launches: set beside the step
loop's own time per step, the difference is what launching costs. DRAM bytes (dram__bytes_read.sum,
dram__bytes_write.sum) are summed instead, per step, and with N (the disks) per particle-step."""
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
    metrics = [n for n in names if n in SHOWN]
    summed = [n for n in names if n in SUMMED]
    byte_scale = {"byte": 1, "Kbyte": 1e3, "Mbyte": 1e6, "Gbyte": 1e9}
    k, t = col["Kernel Name"], col["gpu__time_duration.sum"]
    scale = {"ns": 1e-3, "usecond": 1, "us": 1, "msecond": 1e3, "ms": 1e3, "nsecond": 1e-3}.get(units[t], 1)
    agg = {}
    for r in data:
        name = r[k].split("(")[0].split("<")[0].replace("void ", "")
        us = float(r[t].replace(",", "")) * scale
        a = agg.setdefault(name, {"n": 0, "us": 0.0, "m": {m: 0.0 for m in metrics}, "b": {m: 0.0 for m in summed}})
        a["n"] += 1
        a["us"] += us
        for m in summed:
            a["b"][m] += float(r[col[m]].replace(",", "")) * byte_scale.get(units[col[m]], 1)
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
    print("kernel,launches,us_total,us_per_step,share," + ",".join(short) + byte_cols)
    div = steps * (disks if disks else 1.0)
    for name, a in sorted(agg.items(), key=lambda x: -x[1]["us"]):
        vals = ",".join("%.1f" % (a["m"][m] / a["us"]) if a["us"] else "" for m in metrics)
        bytes_ = "".join(",%.1f" % (a["b"][m] / div) for m in summed)
        print("%s,%d,%.1f,%.2f,%.1f%%,%s%s" % (name, a["n"], a["us"], a["us"] / steps, 100 * a["us"] / total, vals,
                                             bytes_))
    totals = "".join(",%.1f" % (sum(a["b"][m] for a in agg.values()) / div) for m in summed)
    print("all,%d,%.1f,%.2f,100%%,%s%s" % (sum(a["n"] for a in agg.values()), total, total / steps,
                                          ",".join("" for _ in metrics), totals))


if __name__ == "__main__":
    main()

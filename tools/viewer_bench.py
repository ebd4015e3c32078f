#!/usr/bin/env python3
"""tools/viewer_bench.py [N] [STEPS]: the viewer's frame rates in a headless Chromium, on a print-mode
gas of N disks (default 1e5) over STEPS steps (default 10), written to bench/tmp by omp:

  drawing: the shown step drawn 60 times, the view moved each time, each picture finished before the
           next (index.html?bench=1), for the 2D canvas and for WebGL;
  reading: the parse of one step's text (the same run);
  playback: play at the fastest speed from step 0 to the last, steps shown per second (reading each
           next step on a worker while the current one is drawn).

Prints the results with the browser, machine and commands; `make` first. bench/viewer.log holds a run."""
import os
import platform
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from browser import Browser, BrowserError, find_chromium  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def sh(cmd, **kw):
    print("# " + cmd)
    sys.stdout.flush()
    subprocess.run(cmd, shell=True, check=True, cwd=ROOT, **kw)


def main(argv):
    n = int(float(argv[0])) if argv else 100000
    steps = int(argv[1]) if len(argv) > 1 else 10
    work = os.path.join(ROOT, "bench", "tmp")
    os.makedirs(work, exist_ok=True)
    inp, out = os.path.join(work, f"viewer_{n}.in"), os.path.join(work, f"viewer_{n}.out")
    exe = find_chromium()
    if not exe:
        print("viewer_bench.py: no chromium-headless-shell", file=sys.stderr)
        return 1
    version = subprocess.run([exe, "--version"], capture_output=True, text=True).stdout.strip()
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")
    print(f"# git {rev}{' (dirty)' if dirty else ''}; {version}; {cpu}, {os.cpu_count()} cores; {platform.platform()}")
    print(f"# date {time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}; "
          f"load average {' '.join(open('/proc/loadavg').read().split()[:3])}")
    sh(f"tools/gen {n} --fraction 0.2 --speed 0.5 --steps {steps} --mode print > {os.path.relpath(inp, ROOT)}")
    sh(f"./omp {os.path.relpath(inp, ROOT)} --quiet > {os.path.relpath(out, ROOT)}")
    print(f"# output: {os.path.getsize(out) / 1e6:.1f} MB, {steps + 1} states of {n} disks")
    page = "file://" + os.path.join(ROOT, "viewer", "index.html")
    q = f"in={inp}&src={out}"
    size = (1000, 760)
    print(f"# window {size[0]} x {size[1]}, device scale 1")
    with Browser(size=size) as b:
        for render in ("2d", "webgl"):
            url = f"{page}?{q}&step={steps // 2}&bench=1&render={render}"
            print(f"# {url.replace(ROOT + '/', '')}")
            if b.open(url, wait=300) != "1":
                print("viewer_bench.py: " + b.eval("document.getElementById('message').textContent"))
                return 1
            print("drawing, " + render + ": " + b.eval("document.getElementById('bench').textContent"))
        url = f"{page}?{q}&step=0"
        print(f"# {url.replace(ROOT + '/', '')}, then playing at the fastest speed to step {steps}")
        b.open(url, wait=300)
        renderer = b.eval("document.querySelector('canvas').dataset.renderer")
        b.eval("document.getElementById('speed').value = '0'")
        shown0 = b.eval("viewer.stats.shown")
        t0 = time.monotonic()
        b.eval("viewer.play()")
        b.wait_for(f"(s => s.startsWith('step {steps} ') && s)(document.getElementById('status').textContent)",
                   wait=600)
        t1 = time.monotonic()
        shown = b.eval("viewer.stats.shown") - shown0
        print(f"playback ({renderer}): {shown} steps of {n} disks in {t1 - t0:.2f} s: "
              f"{shown / (t1 - t0):.1f} steps per second")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except (BrowserError, subprocess.CalledProcessError) as e:
        print(f"viewer_bench.py: {e}", file=sys.stderr)
        sys.exit(1)

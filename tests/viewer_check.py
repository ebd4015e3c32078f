#!/usr/bin/env python3
"""tests/viewer_check.py WORKDIR: the viewer (viewer/index.html) in a headless Chromium, checked
against the outputs it shows. Prints one PASS/FAIL line per check (tests/t_96_viewer.sh counts them).

The colours expected at the disks' centres are computed here from the output's velocities and the
viewer's ramp (its RAMP stops, copied below); the centres' pixels from the output's positions and the
view the canvas publishes (data-scale, data-cx, data-cy: pixel = W/2 + (x - cx) s, H/2 - (y - cy) s)."""
import math
import os
import random
import re
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from browser import Browser, BrowserError, Image  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
VIEWER = "file://" + os.path.join(ROOT, "viewer", "index.html")
RAMP = [(0, (59, 76, 192)), (0.25, (141, 176, 254)), (0.5, (221, 221, 221)), (0.75, (244, 154, 123)),
        (1, (180, 4, 38))]
BOX, BG = (17, 19, 24), (38, 42, 51)
SIZE = (1000, 760)
results = []


def check(name, ok, detail=""):
    results.append(ok)
    print(("PASS " if ok else "FAIL ") + "viewer/" + name + ("" if ok or not detail else ": " + detail))
    sys.stdout.flush()


def ramp(f):
    f = min(max(f, 0.0), 1.0)
    s = 1
    while s < len(RAMP) - 1 and f > RAMP[s][0]:
        s += 1
    (f0, c0), (f1, c1) = RAMP[s - 1], RAMP[s]
    w = (f - f0) / (f1 - f0)
    return tuple(math.floor(c0[c] + (c1[c] - c0[c]) * w + 0.5) for c in range(3))


def header(path):
    recs = [t.strip() for t in open(path).read().split("\n") if t.strip()][:5]
    return {"n": int(recs[0]), "L": float(recs[1]), "r": float(recs[2]), "S": int(recs[3]), "mode": recs[4]}


def states(path, n):
    """The output's states: a list of (step, [(x, y, vx, vy) for each disk])."""
    out, cur = [], []
    for line in open(path):
        t = line.split()
        cur.append(tuple(float(v) for v in t[2:6]))
        if len(cur) == n:
            out.append((int(t[0]), cur))
            cur = []
    return out


def url(inp, out, **extra):
    q = f"in={os.path.relpath(inp, os.path.join(ROOT, 'viewer'))}&src={os.path.relpath(out, os.path.join(ROOT, 'viewer'))}"
    for k, v in extra.items():
        q += f"&{k}={v}"
    return VIEWER + "?" + q


def view_of(b):
    return b.eval("""(() => { const c = document.querySelector('canvas'), d = c.dataset;
        const rects = ['legend', 'info', 'message'].map((id) => document.getElementById(id))
          .filter((e) => !e.hidden).map((e) => { const r = e.getBoundingClientRect();
            return [r.left, r.top, r.right, r.bottom]; });
        return { s: +d.scale, cx: +d.cx, cy: +d.cy, left: +d.left, top: +d.top, W: +d.width, H: +d.height,
                 vmax: +d.vmax, renderer: d.renderer, minpx: +d.minpx, rects,
                 status: document.getElementById('status').textContent }; })()""")


def pixel_of(v, x, y):
    return (v["left"] + v["W"] / 2 + (x - v["cx"]) * v["s"], v["top"] + v["H"] / 2 - (y - v["cy"]) * v["s"])


def covered(v, px, py, pad=4):
    return any(r[0] - pad <= px <= r[2] + pad and r[1] - pad <= py <= r[3] + pad for r in v["rects"])


def close(a, b, tol):
    return all(abs(p - q) <= tol for p, q in zip(a, b))


def picture_checks(name, b, h, state, first_vmax, tol):
    """Disk centres in their speed's colour, empty box where no disk is, the page around the box."""
    v = view_of(b)
    img = Image(b.screenshot())
    disks = state[1]
    r_px = max(h["r"] * v["s"], v["minpx"])
    reach = (r_px + 3) / v["s"]  # box units within which another disk may colour a pixel
    check(f"{name}: colour scale is the first step's fastest speed",
          abs(v["vmax"] - first_vmax) <= 1e-9 * first_vmax, f"{v['vmax']} against {first_vmax}")
    # a grid of cells of side reach, to find neighbours fast
    grid = {}
    for i, (x, y, _, _) in enumerate(disks):
        grid.setdefault((int(x // reach), int(y // reach)), []).append(i)

    def near(x, y, dist, skip=-1):
        gx, gy = int(x // reach), int(y // reach)
        for ax in (gx - 1, gx, gx + 1):
            for ay in (gy - 1, gy, gy + 1):
                for j in grid.get((ax, ay), ()):
                    if j != skip and (disks[j][0] - x) ** 2 + (disks[j][1] - y) ** 2 < dist * dist:
                        return True
        return False

    good = bad = 0
    first_bad = ""
    for i, (x, y, vx, vy) in enumerate(disks):
        px, py = pixel_of(v, x, y)
        ix, iy = int(math.floor(px)), int(math.floor(py))
        if not (0 <= ix < img.width and 0 <= iy < img.height) or covered(v, px, py):
            continue
        if near(x, y, reach, skip=i):
            continue  # another disk's edge may reach this centre
        want = ramp(math.hypot(vx, vy) / first_vmax)
        got = img.pixel(ix, iy)
        if close(got, want, tol):
            good += 1
        else:
            bad += 1
            first_bad = first_bad or f"disk {i} at pixel ({ix}, {iy}): {got}, expected {want}"
    check(f"{name}: {good} disk centres in the colour of their speed", bad == 0 and good >= min(50, len(disks) // 3),
          first_bad or f"only {good} disks checked")
    # empty places inside the box, and the page outside it
    rnd = random.Random(7)
    L = h["L"]
    inside = outside = 0
    first_bad = ""
    for _ in range(4000):
        x, y = rnd.uniform(0, L), rnd.uniform(0, L)
        px, py = pixel_of(v, x, y)
        if min(px - v["left"] - v["W"] / 2 + L / 2 * v["s"], py - v["top"] - v["H"] / 2 + L / 2 * v["s"]) < 0:
            continue
        if (x * v["s"] < 4 or (L - x) * v["s"] < 4 or y * v["s"] < 4 or (L - y) * v["s"] < 4 or covered(v, px, py)
                or near(x, y, reach)):
            continue
        ix, iy = int(math.floor(px)), int(math.floor(py))
        if not (0 <= ix < img.width and 0 <= iy < img.height):
            continue
        got = img.pixel(ix, iy)
        if close(got, BOX, 1):
            inside += 1
        elif not first_bad:
            first_bad = f"box at pixel ({ix}, {iy}): {got}, expected {BOX}"
    for _ in range(400):
        px = v["left"] + rnd.uniform(0, v["W"])
        py = v["top"] + rnd.uniform(0, v["H"])
        x, y = v["cx"] + (px - v["left"] - v["W"] / 2) / v["s"], v["cy"] - (py - v["top"] - v["H"] / 2) / v["s"]
        if -4 / v["s"] < x < L + 4 / v["s"] and -4 / v["s"] < y < L + 4 / v["s"] or covered(v, px, py):
            continue
        got = img.pixel(int(px), int(py))
        if close(got, BG, 1):
            outside += 1
        elif not first_bad:
            first_bad = f"page at pixel ({int(px)}, {int(py)}): {got}, expected {BG}"
    check(f"{name}: empty box ({inside} places) and the page around it ({outside})",
          not first_bad and inside >= 20 and outside >= 20, first_bad or f"only {inside} and {outside} places")
    return v, img


def periodic_checks(b):
    """A run of the periodic box (inputs/periodic/edges_print: disks across the edges and a corner):
    with periodic=1 (and with the checkbox) a disk within r of an edge is drawn on both sides of the
    box and cut at its edges; without it, on one side and over the edge."""
    pin, pout = os.path.join(ROOT, "inputs", "periodic", "edges_print.in"), os.path.join(ROOT, "outputs", "periodic", "edges_print.out")
    h = header(pin)
    L, r = h["L"], h["r"]
    disks = states(pout, h["n"])[0][1]
    first_vmax = max(math.hypot(d[2], d[3]) for d in disks)

    def near(a, c):
        d = a - c
        return d - L if d > L / 2 else (d + L if d < -L / 2 else d)

    # points of each straddling disk: inside the box on the far side of an edge (its image), and
    # outside the box beyond its own edge; each away from every other disk and its images
    probes = []
    for i, (x, y, vx, vy) in enumerate(disks):
        for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            if not ((sx == 1 and x < r) or (sx == -1 and x > L - r) or (sy == 1 and y < r) or (sy == -1 and y > L - r)):
                continue
            ix, iy = x + sx * L, y + sy * L  # the image's centre
            # a point of the image inside the box, 0.3 r from its edge, and one of the disk outside it
            px = (L - 0.3 * r if sx == 1 else 0.3 * r) if sx else y
            inside = (px, y) if sx else (x, L - 0.3 * r if sy == 1 else 0.3 * r)
            outside = (-0.3 * r if sx == 1 else L + 0.3 * r, y) if sx else (x, -0.3 * r if sy == 1 else L + 0.3 * r)
            if (inside[0] - ix) ** 2 + (inside[1] - iy) ** 2 > (0.8 * r) ** 2:
                continue
            if (outside[0] - x) ** 2 + (outside[1] - y) ** 2 > (0.8 * r) ** 2:
                continue
            if any(j != i and near(inside[0], d[0]) ** 2 + near(inside[1], d[1]) ** 2 < (r + 0.5) ** 2 for j, d in enumerate(disks)):
                continue
            probes.append((i, inside, outside, ramp(math.hypot(vx, vy) / first_vmax)))
    check("periodic: edges_print has disks across the edges to look at", len(probes) >= 4, f"{len(probes)} probes")
    for render in ("2d", "webgl"):
        for wrap in (1, 0):
            ready = b.open(url(pin, pout, step=0, render=render, **({"periodic": 1} if wrap else {})))
            v = view_of(b)
            img = Image(b.screenshot())
            want_status = "step 0 of 20, 24 disks" + (", periodic box" if wrap else "")
            bad = []
            for i, inside, outside, col in probes:
                for (x, y), want in ((inside, col if wrap else BOX), (outside, BG if wrap else col)):
                    px, py = pixel_of(v, x, y)
                    got = img.pixel(int(math.floor(px)), int(math.floor(py)))
                    if not close(got, want, 2):
                        bad.append(f"disk {i} at ({x:.2f}, {y:.2f}): {got}, expected {want}")
            check(f"periodic ({render}, periodic={wrap}): status; disks across an edge drawn "
                  f"{'on both sides, cut at the box' if wrap else 'on one side, over the edge'} ({len(probes)} places)",
                  ready == "1" and v["status"] == want_status and not bad,
                  f"ready={ready} status='{v['status']}' " + "; ".join(bad[:3]))
    # the checkbox, and a click on a disk's image across the edge selects the disk
    b.open(url(pin, pout, step=0, render="2d"))
    b.eval("document.getElementById('periodic').click()")
    status = b.eval("document.getElementById('status').textContent")
    v = view_of(b)
    i, inside, _, _ = probes[0]
    b.click(*pixel_of(v, *inside))
    info = b.wait_for("!document.getElementById('info').hidden && document.getElementById('info').textContent")
    check("periodic: the checkbox turns it on; a click on a disk's image selects the disk",
          status.endswith(", periodic box") and info.startswith(f"disk {i}, step 0"), f"{status} / {info.splitlines()[0]}")


def main(work):
    inputs = os.path.join(ROOT, "inputs")
    outputs = os.path.join(ROOT, "outputs")
    ov_in, ov_out = os.path.join(inputs, "overlapping_print.in"), os.path.join(outputs, "overlapping_print.out")
    h = header(ov_in)
    ov = states(ov_out, h["n"])
    first_vmax = max(math.hypot(d[2], d[3]) for d in ov[0][1])

    with Browser(size=SIZE) as b:
        # ---- a print-mode run at a step, drawn both ways ----
        for render, tol in (("2d", 2), ("webgl", 2)):
            name = f"overlapping_print step 5 ({render})"
            ready = b.open(url(ov_in, ov_out, step=5, render=render))
            v = view_of(b)
            check(f"{name}: ready, status", ready == "1" and v["status"] == "step 5 of 30, 200 disks"
                  and v["renderer"] == ("webgl2" if render == "webgl" else "2d"),
                  f"ready={ready} status='{v['status']}' renderer={v['renderer']}")
            picture_checks(name, b, h, ov[5], first_vmax, tol)

        # ---- the periodic box ----
        periodic_checks(b)

        # ---- click a disk, step on with the keyboard ----
        b.open(url(ov_in, ov_out, step=5, render="2d"))
        v = view_of(b)
        target = None
        for i, (x, y, _, _) in enumerate(ov[5][1]):
            px, py = pixel_of(v, x, y)
            others = min((x - o[0]) ** 2 + (y - o[1]) ** 2 for j, o in enumerate(ov[5][1]) if j != i)
            if others > (4 * h["r"]) ** 2 and not covered(v, px, py, 20):
                target = (i, px, py)
                break
        i, px, py = target
        b.click(px, py)
        info = b.wait_for("!document.getElementById('info').hidden && document.getElementById('info').textContent")
        want_x = open(ov_out).read().split("\n")[5 * h["n"] + i].split()[2]
        check(f"click on disk {i}: its index, step and x as printed", info.startswith(f"disk {i}, step 5")
              and f"x  {want_x}" in info, info.replace("\n", " | "))
        b.key("ArrowRight", "ArrowRight", 39)
        status = b.wait_for("(s => s.startsWith('step 6') && s)(document.getElementById('status').textContent)")
        info = b.eval("document.getElementById('info').textContent")
        check("right arrow: step 6, the disk still selected", status == "step 6 of 30, 200 disks"
              and info.startswith(f"disk {i}, step 6"), f"{status} / {info.splitlines()[0]}")
        b.click(v["left"] + 3, v["top"] + v["H"] - 3)
        check("click on no disk: the panel closes", b.wait_for("document.getElementById('info').hidden"))

        # ---- playback to the end ----
        b.open(url(ov_in, ov_out, step=0, render="2d"))
        b.eval("document.getElementById('speed').value = '0'")
        b.key(" ", "Space", 32)
        try:
            status = b.wait_for("(s => s.startsWith('step 30') && s)(document.getElementById('status').textContent)", 30)
        except BrowserError as e:
            status = str(e)
        shown = b.eval("viewer.stats.shown")
        check("space plays to the last step", status == "step 30 of 30, 200 disks" and shown >= 31,
              f"{status}, {shown} steps shown")

        # ---- a perf-mode output: two states, disks smaller than a pixel ----
        rp_in, rp_out = os.path.join(inputs, "random_1000_perf.in"), os.path.join(outputs, "random_1000_perf.out")
        hp = header(rp_in)
        rp = states(rp_out, hp["n"])
        ready = b.open(url(rp_in, rp_out, step=400, render="2d"))
        v = view_of(b)
        check("random_1000_perf step 400: ready, status", ready == "1" and v["status"] == "step 400 of 400, 1000 disks",
              f"ready={ready} status='{v['status']}'")
        picture_checks("random_1000_perf step 400 (2d, disks drawn at the least size)", b, hp, rp[1],
                       max(math.hypot(d[2], d[3]) for d in rp[0][1]), 2)

        # ---- opened with the file pickers (the File, streamed) ----
        b.open(VIEWER)
        doc = b.call("DOM.getDocument", session=True)["root"]["nodeId"]
        for pick, path in (("#pick-in", ov_in), ("#pick-out", ov_out)):
            node = b.call("DOM.querySelector", {"nodeId": doc, "selector": pick}, session=True)["nodeId"]
            b.call("DOM.setFileInputFiles", {"nodeId": node, "files": [path]}, session=True)
        try:
            status = b.wait_for("(s => s.startsWith('step 0') && document.body.dataset.ready && s)"
                                "(document.getElementById('status').textContent)", 20)
        except BrowserError as e:
            status = str(e)
        check("files chosen with the pickers open at step 0", status == "step 0 of 30, 200 disks", status)

        # ---- bad outputs: a message in the page, naming the file and line ----
        lines = open(ov_out).read().split("\n")
        n = h["n"]

        def write(name, text):
            p = os.path.join(work, name)
            with open(p, "w") as f:
                f.write(text)
            return p

        cut = write("cut.out", "\n".join(lines[:7 * n + 50]) + "\n")
        garbage_line = 3 * n + 17  # 0-based: inside step 3
        g = list(lines)
        g[garbage_line] = "hello there"
        garbage = write("garbage.out", "\n".join(g))
        sw = list(lines)
        sw[2 * n + 40], sw[2 * n + 41] = sw[2 * n + 41], sw[2 * n + 40]
        swapped = write("swapped.out", "\n".join(sw))
        other_in = os.path.join(inputs, "random_300_print.in")
        cases = [
            ("an output cut in a step", ov_in, cut, 3, "the output ends in the middle of step 7"),
            ("a garbage line", ov_in, garbage, 3, f"overlapping_print"),
            ("the output of another input (N = 200 for N = 300)", other_in, ov_out, 0, None),
            ("the output of another input, a later step", other_in, ov_out, 20, None),
            ("a missing file", ov_in, os.path.join(work, "no_such.out"), 0, "cannot read it"),
            ("two lines swapped", ov_in, swapped, 2, f"swapped.out:{2 * n + 41}: disk 40 expected, found '2 41 "),
        ]
        for what, i_path, o_path, step, want in cases:
            ready = b.open(url(i_path, o_path, step=step, render="2d"))
            msg = b.eval("(m => m.hidden ? '' : m.textContent)(document.getElementById('message'))")
            if what == "a garbage line":
                want = f"garbage.out:{garbage_line + 1}: "
                ok = want in msg and "hello there" in msg
            elif want is None:
                # found at step 0's line 201 (a new step begins) or where the index meets step 1
                ok = re.search(r"overlapping_print\.out:(201|301): .*of another input", msg) is not None
            else:
                ok = want in msg
            check(f"{what}: the page says so", ready == "error" and ok, f"ready={ready} message='{msg}'")

    # ---- from a static HTTP server ----
    port_file = os.path.join(work, "port")
    server = subprocess.Popen([sys.executable, "-c", f"""
import http.server, socketserver, functools, sys
h = functools.partial(http.server.SimpleHTTPRequestHandler, directory={ROOT!r})
http.server.SimpleHTTPRequestHandler.log_message = lambda *a: None
with socketserver.TCPServer(('127.0.0.1', 0), h) as s:
    open({port_file!r}, 'w').write(str(s.server_address[1]))
    s.serve_forever()
"""])
    try:
        for _ in range(100):
            if os.path.exists(port_file) and open(port_file).read():
                break
            time.sleep(0.05)
        port = open(port_file).read()
        with Browser(size=SIZE) as b:
            ready = b.open(f"http://127.0.0.1:{port}/viewer/index.html?in=../inputs/overlapping_print.in"
                           f"&src=../outputs/overlapping_print.out&step=12")
            status = b.eval("document.getElementById('status').textContent")
            check("served over HTTP: step 12", ready == "1" and status == "step 12 of 30, 200 disks",
                  f"ready={ready} status='{status}'")
    finally:
        server.kill()
        os.remove(port_file)
    return 0 if all(results) else 1


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1]))
    except BrowserError as e:
        print(f"FAIL viewer: the browser: {e}")
        sys.exit(1)

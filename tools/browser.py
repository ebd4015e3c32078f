#!/usr/bin/env python3
"""tools/browser.py: drives a headless Chromium over the DevTools protocol (on a pipe: no network, no
packages), for the viewer's tests and measurements: open a page, wait until it says it is ready, run
JavaScript in it, click and press keys, take screenshots, and read PNG files.

    tools/browser.py shot URL FILE.png [--size W,H] [--wait SECONDS]
        opens URL, waits until document.body.dataset.ready is set, writes a screenshot
    tools/browser.py eval URL EXPRESSION [--size W,H]
        opens URL, waits likewise, prints the expression's value as JSON

As a module: with Browser(size=(W, H)) as b: b.open(url); b.eval("..."); b.screenshot() -> Image.
Needs chromium-headless-shell (Debian package of the same name) or CHROMIUM=path.
"""
import base64
import json
import os
import shutil
import struct
import subprocess
import sys
import time
import zlib


def find_chromium():
    for name in (os.environ.get("CHROMIUM"), "chromium-headless-shell", "chromium", "chromium-browser"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


class BrowserError(Exception):
    pass


class Browser:
    """One headless browser with one page, spoken to on the pipe of --remote-debugging-pipe (commands
    on its fd 3, replies on its fd 4, each message JSON ending in a NUL byte)."""

    def __init__(self, size=(1000, 760), extra=()):
        exe = find_chromium()
        if not exe:
            raise BrowserError("no chromium-headless-shell (apt-get install chromium-headless-shell)")
        cmd_r, self.cmd_w = os.pipe()
        self.rep_r, rep_w = os.pipe()
        headless = [] if "headless-shell" in os.path.basename(exe) else ["--headless"]
        args = [exe, *headless, "--no-sandbox", "--remote-debugging-pipe", "--allow-file-access-from-files",
                "--hide-scrollbars", f"--window-size={size[0]},{size[1]}", *extra, "about:blank"]
        self.proc = subprocess.Popen(["sh", "-c", f'exec "$@" 3<&{cmd_r} 4>&{rep_w}', "sh", *args],
                                     pass_fds=(cmd_r, rep_w), stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(cmd_r)
        os.close(rep_w)
        self.buf = b""
        self.next_id = 0
        self.events = []
        self.console = []
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        self.call("Page.enable", session=True)
        self.call("Runtime.enable", session=True)
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": size[0], "height": size[1], "deviceScaleFactor": 1, "mobile": False}, session=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.proc.poll() is None:
            try:
                self.call("Browser.close", timeout=5)
            except (BrowserError, OSError):
                pass
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        for fd in (self.cmd_w, self.rep_r):
            try:
                os.close(fd)
            except OSError:
                pass

    def call(self, method, params=None, session=False, timeout=60):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        os.write(self.cmd_w, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout
        while True:
            reply = self._message(end)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})
            if reply.get("method") == "Runtime.consoleAPICalled":
                self.console.append(" ".join(str(a.get("value", a.get("description", "")))
                                             for a in reply["params"].get("args", [])))
            elif reply.get("method") == "Runtime.exceptionThrown":
                d = reply["params"]["exceptionDetails"]
                self.console.append("exception: " + d.get("exception", {}).get("description", d.get("text", "")))

    def _message(self, end):
        import select
        while b"\0" not in self.buf:
            left = end - time.monotonic()
            if left <= 0:
                raise BrowserError("the browser did not answer in time")
            ready, _, _ = select.select([self.rep_r], [], [], left)
            if ready:
                chunk = os.read(self.rep_r, 1 << 20)
                if not chunk:
                    raise BrowserError("the browser exited")
                self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def eval(self, expression, timeout=60):
        """The value of a JavaScript expression (promises awaited), as JSON values."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                           "awaitPromise": True}, session=True, timeout=timeout)
        if "exceptionDetails" in r:
            d = r["exceptionDetails"]
            raise BrowserError("script: " + d.get("exception", {}).get("description", d.get("text", "?")))
        return r["result"].get("value")

    def open(self, url, wait=30):
        """Loads url and waits until the page sets document.body.dataset.ready; returns its value."""
        self.call("Page.navigate", {"url": url}, session=True)
        end = time.monotonic() + wait
        while time.monotonic() < end:
            try:
                ready = self.eval("document.body ? document.body.dataset.ready || '' : ''")
            except BrowserError:
                ready = ""
            if ready:
                return ready
            time.sleep(0.05)
        raise BrowserError(f"{url}: not ready after {wait} s")

    def wait_for(self, expression, wait=30):
        end = time.monotonic() + wait
        while time.monotonic() < end:
            v = self.eval(expression)
            if v:
                return v
            time.sleep(0.05)
        raise BrowserError(f"waited {wait} s for {expression}")

    def click(self, x, y):
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left",
                                                   "clickCount": 1}, session=True)

    def key(self, key, code, keycode):
        for kind in ("keyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", {"type": kind, "key": key, "code": code,
                                                 "windowsVirtualKeyCode": keycode}, session=True)

    def screenshot(self):
        data = self.call("Page.captureScreenshot", {"format": "png"}, session=True)["data"]
        return base64.b64decode(data)


class Image:
    """A PNG's pixels: 8-bit RGB or RGBA, not interlaced (what browsers write)."""

    def __init__(self, png):
        if png[:8] != b"\x89PNG\r\n\x1a\n":
            raise ValueError("not a PNG")
        pos, idat = 8, b""
        while pos < len(png):
            length, kind = struct.unpack(">I4s", png[pos:pos + 8])
            body = png[pos + 8:pos + 8 + length]
            if kind == b"IHDR":
                self.width, self.height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
                if depth != 8 or colour not in (2, 6) or interlace:
                    raise ValueError(f"PNG of depth {depth}, colour type {colour}: not read here")
                self.channels = 3 if colour == 2 else 4
            elif kind == b"IDAT":
                idat += body
            pos += 12 + length
        raw, bpp = zlib.decompress(idat), self.channels
        stride = self.width * bpp
        rows, prev = [], bytearray(stride)
        for y in range(self.height):
            f = raw[y * (stride + 1)]
            line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                if f == 1:
                    line[i] = (line[i] + a) & 255
                elif f == 2:
                    line[i] = (line[i] + b) & 255
                elif f == 3:
                    line[i] = (line[i] + (a + b) // 2) & 255
                elif f == 4:
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
            rows.append(bytes(line))
            prev = line
        self.rows = rows

    def pixel(self, x, y):
        row, k = self.rows[y], x * self.channels
        return tuple(row[k:k + 3])


def main(argv):
    if len(argv) < 3 or argv[0] not in ("shot", "eval"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    size, wait = (1000, 760), 30.0
    rest = argv[3:]
    while rest:
        if rest[0] == "--size" and len(rest) > 1:
            size = tuple(int(v) for v in rest[1].split(","))
        elif rest[0] == "--wait" and len(rest) > 1:
            wait = float(rest[1])
        else:
            print(f"browser.py: unknown option {rest[0]}", file=sys.stderr)
            return 2
        rest = rest[2:]
    try:
        with Browser(size=size) as b:
            ready = b.open(argv[1], wait=wait)
            if argv[0] == "shot":
                with open(argv[2], "wb") as f:
                    f.write(b.screenshot())
                if ready == "error":
                    print("browser.py: the page shows: " + b.eval("document.getElementById('message')"
                                                                   ".textContent"), file=sys.stderr)
            else:
                print(json.dumps(b.eval(argv[2])))
    except BrowserError as e:
        print(f"browser.py: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

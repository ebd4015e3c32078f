#!/usr/bin/env python3
"""Derivation aid for the hard cases (not run by the suite; needs only Python 3).

Works SPEC.md section 3 through on a case with exact rationals. Every arithmetic result is checked to
be a double exactly (dyadic, at most 53 significant bits), so the IEEE computation of the spec makes no
rounding at all and its result is the rational answer written out in README.md. Signed zeros follow the
IEEE rules (x + y == 0 is +0 unless both are -0; products and quotients take the xor of the signs).
A value that needed rounding is marked inexact; printing an inexact value is an error.

usage: tests/hard/derive.py [--inexact] [--periodic] CASE.in  ->  the expected stdout on stdout

With --inexact it skips the exactness checks and prints whatever IEEE double arithmetic gives: an
independent implementation of SPEC.md section 3 (Python floats are IEEE doubles, never fused), used to
cross-check seq on scenes whose numbers are not dyadic. With --periodic it works SPEC.md section 7
(the periodic box: no walls, nearest images, coordinates brought into [0, L) by fmod, exact too)
instead.
"""
import math
import sys
from fractions import Fraction as Q

EXACT = True


class X:
    """A double that remembers whether it is the exact rational result of its operations."""

    def __init__(self, v, ok=True):
        self.v = float(v)
        self.ok = ok

    def _op(self, o, f, g):
        o = o if isinstance(o, X) else X(o)
        r = f(self.v, o.v)
        ok = self.ok and o.ok
        if EXACT and ok and math.isfinite(r) and math.isfinite(self.v) and math.isfinite(o.v):
            ok = Q(r) == g(Q(self.v), Q(o.v))
        return X(r, ok)

    def __add__(self, o): return self._op(o, lambda a, b: a + b, lambda a, b: a + b)
    def __sub__(self, o): return self._op(o, lambda a, b: a - b, lambda a, b: a - b)
    def __mul__(self, o): return self._op(o, lambda a, b: a * b, lambda a, b: a * b)
    def __truediv__(self, o): return self._op(o, lambda a, b: a / b, lambda a, b: a / b)
    def __neg__(self): return X(-self.v, self.ok)
    def __lt__(self, o): return self.v < (o.v if isinstance(o, X) else o)
    def __le__(self, o): return self.v <= (o.v if isinstance(o, X) else o)
    def __gt__(self, o): return self.v > (o.v if isinstance(o, X) else o)
    def __eq__(self, o): return self.v == (o.v if isinstance(o, X) else o)
    __hash__ = None


def sqrt(a):
    r = math.sqrt(a.v)
    return X(r, a.ok and (not EXACT or Q(r) * Q(r) == Q(a.v)))


INF = X(math.inf)


def wall_time(c, v, lo, hi):
    t = INF
    if v > 0: t = (hi - c) / v
    if v < 0: t = (lo - c) / v
    if t < 0: t = X(0.0, t.ok)
    return t


PERIODIC = None  # (L, half) with --periodic


def wrap(d):
    """SPEC.md 7's nearest image of a difference of two coordinates (the identity without --periodic)."""
    if PERIODIC is None: return d
    L, half = PERIODIC
    if d > half: return d - L
    if d < -half: return d + L
    return d


def into_box(c):
    """SPEC.md 7: x = fmod(x, L); if (x < 0) x += L; if (x >= L) x -= L (fmod is exact)."""
    L = PERIODIC[0]
    c = X(math.fmod(c.v, L.v), c.ok)
    if c < 0: c = c + L
    if not c < L: c = c - L
    return c


def pair_time(p, q, sigma2):
    dx, dy = wrap(q[0] - p[0]), wrap(q[1] - p[1])
    dvx, dvy = q[2] - p[2], q[3] - p[3]
    b = dx * dvx + dy * dvy
    dd = dx * dx + dy * dy
    a = dvx * dvx + dvy * dvy
    c = dd - sigma2
    D = b * b - a * c
    if not (b < 0 and dd > 0 and D > 0): return None
    t = c / (-b + sqrt(D))
    if t < 0: t = X(0.0, t.ok)
    return t if t <= 1 else None


def finish(d, t1, lo, hi):
    rem = X(1) - t1
    if PERIODIC is not None:  # no wall, no stop
        d[0], d[1] = d[0] + d[2] * rem, d[1] + d[3] * rem
        return
    tx, ty = wall_time(d[0], d[2], lo, hi), wall_time(d[1], d[3], lo, hi)
    t2 = ty if ty < tx else tx
    if t2 <= rem:
        d[0] = (hi if d[2] > 0 else lo) if tx == t2 else d[0] + d[2] * t2
        d[1] = (hi if d[3] > 0 else lo) if ty == t2 else d[1] + d[3] * t2
    else:
        d[0] = d[0] + d[2] * rem
        d[1] = d[1] + d[3] * rem


def step(ds, cnt, lo, hi, sigma2):
    n = len(ds)
    ev = []
    for i in range(n if PERIODIC is None else 0):
        tx, ty = wall_time(ds[i][0], ds[i][2], lo, hi), wall_time(ds[i][1], ds[i][3], lo, hi)
        tw = ty if ty < tx else tx
        if tw <= 1: ev.append((tw, 0, i, i))
    for i in range(n):
        for j in range(i + 1, n):
            t = pair_time(ds[i], ds[j], sigma2)
            if t is not None: ev.append((t, 1, i, j))
    ev.sort(key=lambda e: (e[0].v, e[1], e[2], e[3]))
    taken = {}
    for e in ev:
        if e[2] in taken or e[3] in taken: continue
        if EXACT and not e[0].ok: sys.exit("accepted event with an inexact time: %r" % (e,))
        taken[e[2]] = taken[e[3]] = e
    for i in range(n):
        if i not in taken:
            d = ds[i]
            d[0], d[1] = d[0] + d[2], d[1] + d[3]
            continue
        t1, kind, a, b = taken[i]
        if kind == 0:
            d = ds[i]
            tx, ty = wall_time(d[0], d[2], lo, hi), wall_time(d[1], d[3], lo, hi)
            if tx == t1: d[0], d[2] = (hi if d[2] > 0 else lo), -d[2]
            else: d[0] = d[0] + d[2] * t1
            if ty == t1: d[1], d[3] = (hi if d[3] > 0 else lo), -d[3]
            else: d[1] = d[1] + d[3] * t1
            finish(d, t1, lo, hi)
            cnt[i][1] += 1
        elif i == a:
            p, q = ds[a], ds[b]
            for d in (p, q):
                d[0], d[1] = d[0] + d[2] * t1, d[1] + d[3] * t1
            nx, ny = wrap(q[0] - p[0]), wrap(q[1] - p[1])
            ln = sqrt(nx * nx + ny * ny)
            if not ln == 0:
                ux, uy = nx / ln, ny / ln
                vni, vti = ux * p[2] + uy * p[3], ux * p[3] - uy * p[2]
                vnj, vtj = ux * q[2] + uy * q[3], ux * q[3] - uy * q[2]
                p[2], p[3] = vnj * ux - vti * uy, vnj * uy + vti * ux
                q[2], q[3] = vni * ux - vtj * uy, vni * uy + vtj * ux
            finish(p, t1, lo, hi)
            finish(q, t1, lo, hi)
            cnt[a][0] += 1
            cnt[b][0] += 1
    for d in ds:
        for k in (0, 1):
            if PERIODIC is not None:
                d[k] = into_box(d[k])
                continue
            if d[k] < lo: d[k] = lo
            if d[k] > hi: d[k] = hi


def fmt(v):
    if EXACT and not v.ok: sys.exit("an output value is inexact: %r" % v.v)
    return "%.8f" % v.v


def main():
    global EXACT, PERIODIC
    args = sys.argv[1:]
    periodic = False
    while args[0] in ("--inexact", "--periodic"):
        EXACT = EXACT and args[0] != "--inexact"
        periodic = periodic or args[0] == "--periodic"
        args = args[1:]
    tok = [l.split() for l in open(args[0]) if l.strip()]
    n, L, r, S, mode = int(tok[0][0]), X(tok[1][0]), X(tok[2][0]), int(tok[3][0]), tok[4][0]
    if periodic: PERIODIC = (L, L / X(2))
    ds = [None] * n
    for t in tok[5:]:
        ds[int(t[0])] = [X(s) for s in t[1:5]]
    lo, hi = r, L - r
    sigma2 = (r + r) * (r + r)
    if not (hi.ok and sigma2.ok): sys.exit("hi or sigma2 inexact")
    cnt = [[0, 0] for _ in range(n)]
    out = []
    def emit(s, counts):
        for i, d in enumerate(ds):
            line = "%d %d %s" % (s, i, " ".join(fmt(v) for v in d))
            if counts: line += " %d %d" % tuple(cnt[i])
            out.append(line)
    emit(0, False)
    for s in range(1, S + 1):
        step(ds, cnt, lo, hi, sigma2)
        if mode == "print" and s < S: emit(s, False)
    emit(S, True)
    sys.stdout.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Parameter sweeps behind docs/mesh-general.md (sections 6.2 and 6.4).

These are measurements, not proofs: they evaluate the triangulation rules on a dense grid
of configurations and print the worst angles found. Usage:
  mesh_general_sweep.py band [EPS]   band cells, perpendicular-foot warp, EPS = shift along
                                     the constraint in cell sides (default 1/32)
  mesh_general_sweep.py band-vert    band cells, vertical warp (the simpler rule)
  mesh_general_sweep.py star [R]     2x2 star fan, star vertex within R of the centre
"""
import math
import sys


def orient(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def angles(tri):
    """The three angles in degrees; None when the triangle is not counter-clockwise."""
    if orient(*tri) <= 0:
        return None
    out = []
    for i in range(3):
        p, q, r = tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]
        u = (q[0] - p[0], q[1] - p[1])
        w = (r[0] - p[0], r[1] - p[1])
        out.append(math.degrees(math.atan2(abs(u[0] * w[1] - u[1] * w[0]), u[0] * w[0] + u[1] * w[1])))
    return out


def split_quad(q):
    """A convex quadrilateral (counter-clockwise) split along its shorter diagonal."""
    if math.dist(q[0], q[2]) <= math.dist(q[1], q[3]):
        return [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    return [(q[1], q[2], q[3]), (q[1], q[3], q[0])]


class Worst:
    def __init__(self):
        self.lo, self.hi, self.bad, self.at_lo, self.at_hi = 180.0, 0.0, 0, None, None

    def add(self, tris, where):
        for t in tris:
            a = angles(t)
            if a is None:
                self.bad += 1
                continue
            if min(a) < self.lo:
                self.lo, self.at_lo = min(a), where
            if max(a) > self.hi:
                self.hi, self.at_hi = max(a), where

    def report(self, name):
        print(f"{name}: min {self.lo:.4f} at {self.at_lo}, max {self.hi:.4f} at {self.at_hi}, "
              f"inverted {self.bad}")


def band(eps, perpendicular=True, n=160):
    """Column [0,1] of a unit grid; the constraint crosses x=0 at y0 in [-1/2,1/2] with slope
    tau in [0,1]; chain corners (0,0) and (1,r); warp them onto the constraint."""
    w = Worst()
    for i in range(n + 1):
        y0 = -0.5 + i / n
        for j in range(n + 1):
            tau = j / n
            y1 = y0 + tau
            if y1 >= 1.5:
                continue
            r = 0 if y1 < 0.5 else 1
            d = (1 / math.hypot(1, tau), tau / math.hypot(1, tau))

            def warp(x, yc, row, e):
                if perpendicular:
                    k = (row - yc) * d[1]
                    p = (x + k * d[0], yc + k * d[1])
                else:
                    p = (x, yc)
                return (p[0] + e * d[0], p[1] + e * d[1])

            for e0 in (-eps, 0, eps):
                for e1 in (-eps, 0, eps):
                    q0, q1 = warp(0, y0, 0, e0), warp(1, y1, r, e1)
                    if r == 0:
                        tris = split_quad([q0, q1, (1, 1), (0, 1)]) + split_quad([(0, -1), (1, -1), q1, q0])
                    else:
                        tris = [(q0, (1, 0), q1), (q0, q1, (0, 1))]
                        tris += split_quad([(0, -1), (1, -1), (1, 0), q0])
                        tris += split_quad([(0, 1), q1, (1, 2), (0, 2)])
                    w.add(tris, (round(y0, 4), round(tau, 4), e0, e1))
    return w


STAR = [(-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0)]


def star(radius, eps=1 / 32, n=17, m=1440):
    """Star vertex v in [-radius, radius]^2 around the centre of the 2x2 star [-1,1]^2; one
    constraint from v in each of m directions; its exit corner (the star corner nearest its
    exit point) is warped onto it; the fan from v to the star boundary is measured."""
    w = Worst()
    steps = [0.0] if radius == 0 else [radius * (-1 + 2 * i / (n - 1)) for i in range(n)]
    for a in steps:
        for b in steps:
            for k in range(m):
                phi = 2 * math.pi * (k + 0.5) / m
                d = (math.cos(phi), math.sin(phi))
                tx = (math.copysign(1, d[0]) - a) / d[0]
                ty = (math.copysign(1, d[1]) - b) / d[1]
                t = min(tx, ty)
                c = (round(a + t * d[0]), round(b + t * d[1]))
                foot = (c[0] - a) * d[0] + (c[1] - b) * d[1]
                for e in (-eps, 0, eps):
                    q = (a + (foot + e) * d[0], b + (foot + e) * d[1])
                    ring = [q if p == c else p for p in STAR]
                    w.add([((a, b), ring[i], ring[(i + 1) % 8]) for i in range(8)],
                          (a, b, round(math.degrees(phi), 3), e))
    return w


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "band"
    if what == "band":
        eps = float(eval(sys.argv[2])) if len(sys.argv) > 2 else 1 / 32
        band(eps).report(f"band, perpendicular warp, eps {eps}")
    elif what == "band-vert":
        band(0.0, perpendicular=False).report("band, vertical warp")
    elif what == "star":
        r = float(eval(sys.argv[2])) if len(sys.argv) > 2 else 0.0
        star(r).report(f"star, vertex within {r} of the centre")
    else:
        sys.exit(__doc__)

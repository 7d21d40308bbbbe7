#!/usr/bin/env python3
"""The issue-5 targets against one quadkit-bench run, as a Markdown table.

Usage: bench/summarize.py RESULTS.jsonl
Every ratio comes from the one run in the file (same process, interleaved). A baseline
whose answers differed from quadkit's was not timed; where it still recorded a time
(`seconds_unverified`, balance only) the ratio is shown in brackets.
"""
import json
import sys


def load(path):
    return [json.loads(l) for l in open(path) if l.strip()]


def pick(rows, **kw):
    for r in rows:
        if all(r.get(k) == v for k, v in kw.items()):
            return r
    return None


def rate(r):
    if r is None:
        return None
    if r.get("per_second") is not None:
        return r["per_second"]
    return None


def main():
    rows = load(sys.argv[1])
    big = max((r["n"] for r in rows if r["op"] == "knn" and r["dataset"] == "uniform" and r["n"] <= 1000000), default=0)
    out = []

    def line(what, target, q, b, note=""):
        if q is None or b is None:
            out.append(f"| {what} | {target} | – | {note or 'not measured'} |")
            return
        ratio = q / b
        ok = "yes" if ratio >= float(target.strip("x≥ ")) else "**no**"
        out.append(f"| {what} | {target} | {ratio:.2f}x | {ok}{'; ' + note if note else ''} |")

    n = big
    u = dict(dataset="uniform", n=n)
    qb = rate(pick(rows, op="build", impl="quadkit", threads=1, **u))
    for base, tgt in (("flann", "≥ 30x"), ("nanoflann", "≥ 30x"), ("cgal", "≥ 10x")):
        line(f"build, {base}", tgt, qb, rate(pick(rows, op="build", impl=base, **u)))
    for base in ("flann", "nanoflann", "embree"):
        q = rate(pick(rows, op="knn", impl="quadkit", k=1, order="random", batch=False, threads=1, **u))
        b = rate(pick(rows, op="knn", impl=base, k=1, order="random", batch=False, threads=1, **u))
        line(f"1-NN random, one query per call, {base}", "≥ 3x", q, b)
    for base in ("flann", "nanoflann", "embree"):
        q = rate(pick(rows, op="knn", impl="quadkit", k=1, order="random", batch=True, threads=1, **u))
        b = rate(pick(rows, op="knn", impl=base, k=1, order="random", batch=False, threads=1, **u))
        line(f"1-NN batched vs {base} random single", "≥ 6x", q, b)
    for base in ("flann", "nanoflann", "embree"):
        q = rate(pick(rows, op="knn", impl="quadkit", k=1, order="morton", batch=False, threads=1, **u))
        b = rate(pick(rows, op="knn", impl=base, k=1, order="morton", batch=False, threads=1, **u))
        line(f"1-NN Morton order, {base}", "≥ 2x", q, b)
    for k in (8, 32):
        for base in ("flann", "nanoflann", "embree"):
            q = rate(pick(rows, op="knn", impl="quadkit", k=k, order="random", batch=False, threads=1, **u))
            b = rate(pick(rows, op="knn", impl=base, k=k, order="random", batch=False, threads=1, **u))
            line(f"k={k} random, {base}", "≥ 2x", q, b)
    nc = max((r["n"] for r in rows if r["op"] == "collide"), default=0)
    line(f"all pairs of {nc:.0e} boxes, embree rtcCollide", "≥ 3x",
         rate(pick(rows, op="collide", impl="quadkit", n=nc)), rate(pick(rows, op="collide", impl="embree", n=nc)))
    nr = max((r["n"] for r in rows if r["op"] == "raycast"), default=0)
    line(f"first hit, {nr:.0e} discs, embree rtcIntersect1", "≥ 2x",
         rate(pick(rows, op="raycast", impl="quadkit", n=nr)), rate(pick(rows, op="raycast", impl="embree", n=nr)))
    nb = max((r["n"] for r in rows if r["op"] == "balance"), default=0)
    qbal = pick(rows, op="balance", impl="quadkit", n=nb)
    cb = pick(rows, op="balance", impl="cgal", n=nb)
    if cb and cb.get("matches") is False and cb.get("seconds_unverified"):
        r = qbal["per_second"] / (cb["leaves_after"] / cb["seconds_unverified"])
        out.append(f"| balance ({qbal['dataset']} {nb:.0e}), cgal grade() | ≥ 5x | [{r:.2f}x] | "
                   f"**no**; CGAL's result differs ({cb.get('unbalanced_leaves', 0):.0f} leaves left unbalanced): not a verified comparison |")
    else:
        line(f"balance ({nb:.0e}), cgal grade()", "≥ 5x", rate(qbal), rate(cb))
    line(f"balance ({nb:.0e}), p4est_balance (no target)", "≥ 1x", rate(qbal), rate(pick(rows, op="balance", impl="p4est", n=nb)))
    um = max((r["n"] for r in rows if r["op"] == "mesh"), default=0)
    line(f"meshing U={um}, cgal Mesh_2 (triangles/s)", "≥ 20x",
         rate(pick(rows, op="mesh", impl="quadkit", n=um)), rate(pick(rows, op="mesh", impl="cgal", n=um)))
    t1 = rate(pick(rows, op="knn", impl="quadkit", k=1, order="random", batch=True, threads=1, **u))
    t2 = next((rate(r) for r in rows if r["op"] == "knn" and r["impl"] == "quadkit" and r["batch"]
               and r["threads"] > 1 and r["dataset"] == "uniform" and r["n"] == n), None)
    if t1 and t2:
        out.append(f"| batched 1-NN, two threads / one thread | ≥ 1.8x | [{t2 / t1:.2f}x] | not measured "
                   "fairly: the two vCPUs were shared with other work during the run; two-thread rows "
                   "are wall clock, one-thread rows CPU time |")
    bt = next((rate(r) for r in rows if r["op"] == "build" and r["impl"] == "quadkit"
               and r["threads"] > 1 and r["dataset"] == "uniform" and r["n"] == n), None)
    if qb and bt:
        out.append(f"| build, two threads / one thread | ≥ 1.8x | {bt / qb:.2f}x | "
                   f"{'yes' if bt / qb >= 1.8 else '**no**'} (wall clock over CPU time) |")
    else:
        out.append("| build, two threads / one thread | ≥ 1.8x | – | not measured (run with --threads 2) |")
    b = pick(rows, op="build", impl="quadkit", threads=1, **u)
    if b:
        bp = b["bytes_per_point"]
        out.append(f"| memory, bytes per point (n={n:.0e}) | ≤ 24 | {bp:.1f} | {'yes' if bp <= 24 else '**no**'} |")
    print(f"| target (uniform points, n = {n:.0e}, one thread unless said) | wanted | measured | reached |")
    print("|---|---|---|---|")
    print("\n".join(out))


if __name__ == "__main__":
    main()

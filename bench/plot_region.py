#!/usr/bin/env python3
"""Plot `quadkit-bench --op region` results as one SVG (Python standard library only).

Usage:
  bench/plot_region.py --bench BUILD/bench/quadkit-bench [--n N] [--threads T] [-o SVG]
      runs the region benchmark (writing its JSON lines to bench/results/region.jsonl),
      then draws it; the one command to redo docs/img/region-bench.svg on an idle machine.
  bench/plot_region.py RESULTS.jsonl [-o SVG]
      draws from JSON lines already written (any run holding region rows).

The picture has three panels: points located per second for each point set and
implementation (quadkit batch, one call per point, batch on T threads; GEOS; S2), build
time per layer, and memory per layer (quadkit: the layer's own count; GEOS and S2: heap
growth over their build and 1e5 queries). Rates marked * come from a baseline whose
answers differ from quadkit's on a few boundary points (the JSON lines count them).
"""
import argparse
import json
import os
import subprocess
import sys

COLORS = {"quadkit batch": "#1f6fb4", "quadkit single": "#6fa8dc", "quadkit batch t": "#0b3d6b",
          "geos": "#d9822b", "s2": "#3a9e4f"}


def load(path):
    return [json.loads(l) for l in open(path) if l.strip()]


def label(r):
    if r["impl"] != "quadkit":
        return r["impl"]
    if r["threads"] > 1:
        return f"quadkit batch t{r['threads']}"
    return "quadkit batch" if r["batch"] else "quadkit single"


def color(lab):
    if lab.startswith("quadkit batch t"):
        return COLORS["quadkit batch t"]
    return COLORS.get(lab, "#888888")


def esc(s):
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def bars(out, y, title, groups, unit, fmt, width=560, x0=190):
    """groups: [(group name, [(label, value, mark)])]; returns the next y."""
    out.append(f'<text x="10" y="{y}" font-size="14" font-weight="bold">{esc(title)}</text>')
    y += 12
    top = max((v for _, items in groups for _, v, _ in items), default=1.0) or 1.0
    for name, items in groups:
        y += 16
        out.append(f'<text x="10" y="{y}" font-size="12" font-weight="bold">{esc(name)}</text>')
        for lab, v, mark in items:
            y += 4
            w = max(1.0, width * v / top)
            out.append(f'<text x="{x0 - 6}" y="{y + 11}" font-size="11" text-anchor="end">'
                       f'{esc(lab)}</text>')
            out.append(f'<rect x="{x0}" y="{y}" width="{w:.1f}" height="14" fill="{color(lab)}"/>')
            out.append(f'<text x="{x0 + w + 4:.1f}" y="{y + 11}" font-size="11">'
                       f'{fmt(v)} {unit}{"*" if mark else ""}</text>')
            y += 14
        y += 4
    return y + 18


def plot(rows, path):
    reg = [r for r in rows if r["op"] == "region" and r.get("per_second")]
    bld = [r for r in rows if r["op"] == "region-build" and r.get("seconds")]
    if not reg:
        sys.exit("plot_region: no region rows in the results")
    order = ["quadkit batch", "quadkit single", "quadkit batch t", "geos", "s2"]
    rate_groups = []
    for ds in dict.fromkeys(r["dataset"] for r in reg):
        items = []
        rs = [r for r in reg if r["dataset"] == ds and r["impl"] != "quadkit-planar"]
        rank = lambda lab: order.index("quadkit batch t" if lab.startswith("quadkit batch t") else lab)
        rs.sort(key=lambda r: (rank(label(r)), label(r)))
        for r in rs:
            items.append((label(r), r["per_second"] / 1e6, r.get("matches") is False))
        rate_groups.append((f"{ds} ({rs[0]['queries']:,} points)", items))
    time_groups, mem_groups = [], []
    for ds in dict.fromkeys(r["dataset"] for r in bld):
        rs = [r for r in bld if r["dataset"] == ds]
        time_groups.append((f"{ds} ({rs[0]['n']:,} vertices)",
                            [(r["impl"], r["seconds"] * 1e3, False) for r in rs]))
        mem = [(r["impl"], r["bytes"] / 1e6, False) for r in rs if r.get("bytes")]
        if mem:
            mem_groups.append((ds, mem))
    out = []
    y = 24
    threads = max(r["threads"] for r in reg)
    y = bars(out, y, f"Points located per second (one thread; t{threads}: {threads} threads)",
             rate_groups, "M/s", lambda v: f"{v:.2f}")
    y = bars(out, y, "Build time (GEOS prepares its indexes lazily: not comparable)", time_groups,
             "ms", lambda v: f"{v:.1f}")
    if mem_groups:
        y = bars(out, y, "Memory (quadkit: the layer's count; GEOS, S2: heap growth)", mem_groups,
                 "MB", lambda v: f"{v:.1f}")
    out.append(f'<text x="10" y="{y}" font-size="10" fill="#555">* answers differ from '
               f'quadkit\'s on a few boundary points (see the JSON lines\' mismatches)</text>')
    y += 10
    head = (f'<svg xmlns="http://www.w3.org/2000/svg" width="860" height="{y}" '
            f'font-family="sans-serif">\n<rect width="100%" height="100%" fill="white"/>\n')
    with open(path, "w") as f:
        f.write(head + "\n".join(out) + "\n</svg>\n")
    print(f"plot_region: wrote {path}", file=sys.stderr)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("results", nargs="?", help="JSON lines of a quadkit-bench run")
    ap.add_argument("--bench", help="run this quadkit-bench with --op region first")
    ap.add_argument("--n", type=int, default=1000000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("-o", default=os.path.join(root, "docs", "img", "region-bench.svg"))
    a = ap.parse_args()
    if a.bench:  # the run's table goes to stdout as usual
        a.results = a.results or os.path.join(root, "bench", "results", "region.jsonl")
        os.makedirs(os.path.dirname(a.results), exist_ok=True)
        subprocess.run([a.bench, "--op", "region", "--n", str(a.n), "--threads", str(a.threads),
                        "--json-out", a.results], check=True)
    if not a.results:
        ap.error("give RESULTS.jsonl or --bench")
    plot(load(a.results), a.o)


if __name__ == "__main__":
    main()

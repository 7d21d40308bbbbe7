#!/usr/bin/env bash
# Builds quadkit-bench (Release, -DQUADKIT_BUILD_BENCH=ON) in build-bench/, runs the
# suite, writes bench/results/<name>.jsonl and one SVG plot per operation (gnuplot), and
# prints the ratio table. `make bench` installs the baselines first.
#
# Usage: scripts/bench.sh [--quick] [any other quadkit-bench arguments]
#        scripts/bench.sh --targets
#   BUILD_DIR (default build-bench), JOBS (default 2), RESULTS (default bench/results).
#
# --targets runs only what the issues' targets compare, each operation in its own run
# (23 minutes on the 2-vCPU guest, most of it the mesh cases' gmsh and the world at 10^5;
# the full suite takes well over an hour): 1M uniform points (build, kNN), 1M boxes and discs (all pairs, rays), the
# balance at 1M, every mesh case, the world at 10^4 and 10^5 objects and queries on it at
# 10^5, the region layer;
# with --threads 2. It writes RESULTS/targets.jsonl (each run's lines in turn),
# targets.txt (each run's table) and targets-targets.md; no plots.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build-bench}
JOBS=${JOBS:-2}
RESULTS=${RESULTS:-bench/results}

name=full
for a in "$@"; do [ "$a" = "--quick" ] && name=quick; done
targets=0
if [ "${1:-}" = "--targets" ]; then
  targets=1 name=targets
  shift
fi

# PLOT_ONLY=1 redraws the plots (and the targets table) from an existing JSON lines file.
if [ "${PLOT_ONLY:-0}" != 1 ]; then
echo "bench: configuring and building $BUILD_DIR (Release)" >&2
mkdir -p "$BUILD_DIR"
log="$BUILD_DIR/bench-configure.log"
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DQUADKIT_BUILD_BENCH=ON \
  -DQUADKIT_BUILD_TESTS=OFF >"$log" 2>&1 || { cat "$log" >&2; exit 1; }
grep "quadkit-bench baselines" "$log" >&2 || true
nice -n 5 cmake --build "$BUILD_DIR" --target quadkit_bench -j"$JOBS" >/dev/null

fi
mkdir -p "$RESULTS"
jsonl="$RESULTS/$name.jsonl"
table="$RESULTS/$name.txt"
if [ "$targets" = 1 ] && [ "${PLOT_ONLY:-0}" != 1 ]; then
  start=$(date +%s)
  : >"$jsonl"
  : >"$table"
  part=$(mktemp)
  # (each run's JSON lines appended in turn; the table file gets each run's header and rows)
  for run in "--op build --dataset uniform --n 1000000 --threads 2" \
    "--op knn --dataset uniform --n 1000000 --threads 2" \
    "--op collide --n 1000000 --threads 2" \
    "--op raycast --n 1000000 --threads 2" \
    "--op balance --n 1000000" \
    "--op mesh" \
    "--op world --n 10000 --threads 2" \
    "--op world --n 100000 --threads 2" \
    "--op world-query --n 100000 --threads 2" \
    "--op region"; do
    {
      echo "# $(date -u '+%Y-%m-%d %H:%M UTC') $(uname -m), $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg)"
      echo "# command: $BUILD_DIR/bench/quadkit-bench $run"
      # shellcheck disable=SC2086 # (the run's words are its arguments)
      "$BUILD_DIR/bench/quadkit-bench" $run --json-out "$part"
    } | tee -a "$table"
    cat "$part" >>"$jsonl"
  done
  rm -f "$part"
  echo "bench: targets took $(( $(date +%s) - start )) s; results in $jsonl, tables in $table" >&2
fi
if [ "$targets" = 1 ]; then # (PLOT_ONLY=1: the tables again from targets.jsonl)
  python3 bench/summarize.py "$jsonl" | tee "$RESULTS/$name-targets.md"
  exit 0
fi
if [ "${PLOT_ONLY:-0}" != 1 ]; then
threads=2
start=$(date +%s)
{
  echo "# $(date -u '+%Y-%m-%d %H:%M UTC') $(uname -m), $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# command: $BUILD_DIR/bench/quadkit-bench --threads $threads $* --json-out $jsonl"
  "$BUILD_DIR/bench/quadkit-bench" --threads "$threads" "$@" --json-out "$jsonl"
} | tee "$table"
echo "bench: suite took $(( $(date +%s) - start )) s; results in $jsonl, table in $table" >&2
fi
# The issue's targets against this run.
if command -v python3 >/dev/null; then
  python3 bench/summarize.py "$jsonl" | tee "$RESULTS/$name-targets.md"
fi

# Plots: throughput against n for each operation, one line per implementation (and
# variant for kNN), log-log, from the JSON lines just written.
if ! command -v gnuplot >/dev/null; then
  echo "bench: gnuplot not found; no plots" >&2
  exit 0
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 - "$jsonl" "$tmp" <<'PY'
import json, sys, os, collections
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
series = collections.defaultdict(list)
for r in rows:
    if r.get("per_second") is None or r.get("matches") is False:
        continue
    # One plot per operation on the uniform set (the others would crowd it): kNN keeps
    # 1-NN random order single/batch; balance, mesh, collide and raycast have their own set.
    if r["op"] in ("build", "knn", "radius", "range") and r["dataset"] != "uniform":
        continue
    if r["op"] == "knn" and not (r["k"] == 1 and r["order"] == "random" and r["threads"] == 1):
        continue
    label = r["impl"] + (" batch" if r["batch"] else "")
    series[(r["op"], label)].append((r["n"], r["per_second"]))
ops = sorted({op for op, _ in series})
for op in ops:
    with open(os.path.join(sys.argv[2], op + ".plt"), "w") as f:
        labels = sorted(l for o, l in series if o == op)
        for l in labels:
            with open(os.path.join(sys.argv[2], f"{op}.{l.replace(' ', '_')}.dat"), "w") as d:
                for n, v in sorted(series[(op, l)]):
                    d.write(f"{n} {v}\n")
        xl = "domain side U" if op == "mesh" else "n"
        f.write('set terminal svg size 640,400 dynamic font "sans,11"\n')
        what = {"knn": "1-NN, random order, uniform points", "build": "uniform points",
                "radius": "uniform points", "range": "uniform points", "balance": "gauss tree, capacity 8",
                "mesh": "octagons; triangles/s", "collide": "boxes, build + all pairs",
                "raycast": "1e6 rays against n discs", "geo-knn": "cities"}.get(op, "")
        f.write(f'set title "{op}: throughput against {xl} ({what}; one thread)"\n')
        f.write(f'set xlabel "{xl}"\nset ylabel "per second"\nset logscale xy\nset key outside right\nset grid\n')
        plots = [f'"{sys.argv[2]}/{op}.{l.replace(" ", "_")}.dat" using 1:2 with linespoints title "{l}"' for l in labels]
        f.write("plot " + ", ".join(plots) + "\n")
PY
for plt in "$tmp"/*.plt; do
  op=$(basename "$plt" .plt)
  gnuplot "$plt" >"$RESULTS/$name-$op.svg" 2>/dev/null
done
echo "bench: plots in $RESULTS/$name-*.svg" >&2

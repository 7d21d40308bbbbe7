#!/usr/bin/env bash
# `make demo`, world part: a small bouncing-objects simulation (discs, boxes, segments
# and points) with per-frame pair counts and timings as JSON, the last frame drawn with
# the objects in an overlapping pair in red, and a replay of a tiny hand-written scene.
# Usage: scripts/demo-world.sh CLI [OUTDIR]
set -euo pipefail
cli=${1:-build/quadkit}
out=${2:-out/demo}
mkdir -p "$out"

echo "== simulate: 500 bouncing objects, 60 frames (pairs, began, ended per frame; ms per frame)"
"$cli" simulate --n 500 --frames 60 --seed 1 --svg "$out/world.svg" -o "$out/world.json"
head -c 400 "$out/world.json"
echo "..."
echo "   full output: $out/world.json; picture of the last frame: $out/world.svg"

echo "== world: replay of a tiny scene (a disc touches a box, then a segment, then neither)"
printf 'id,kind,x,y,a,b\n1,disc,0,0,1\n2,box,3,-1,5,1\n3,segment,-2,3,6,3\n' >"$out/world-objects.csv"
printf 'frame,id,x,y,a,b\n1,1,2,0,1\n2,1,2,2,1\n3,1,0,0,1\n' >"$out/world-moves.csv"
for which in all began ended; do
  echo "-- pairs $which (frame,a,b)"
  "$cli" world "$out/world-objects.csv" "$out/world-moves.csv" --pairs "$which"
done

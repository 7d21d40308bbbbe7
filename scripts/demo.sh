#!/usr/bin/env bash
# `make demo`: the main job on built-in example data. Outputs go to out/demo/.
set -euo pipefail
cli=${1:-build/quadkit}
out=out/demo
mkdir -p "$out"
echo "== quadtree over examples/points.csv (capacity 1)"
"$cli" tree examples/points.csv --svg "$out/tree.svg"
echo "   picture: $out/tree.svg"
# Later modules add their parts in scripts/demo-*.sh (called with the CLI and the output dir).
for part in scripts/demo-query.sh scripts/demo-mesh.sh scripts/demo-region.sh scripts/demo-world.sh; do
  if [ -f "$part" ]; then bash "$part" "$cli" "$out"; fi
done

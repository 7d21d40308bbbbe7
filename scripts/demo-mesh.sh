#!/usr/bin/env bash
# `make demo`, mesh part: mesh the lecture notes' example (a 1x1 component at (1,1) in a
# 16x16 grid) and a richer input (nested components, a thin diagonal strip, a component
# on the domain's edge, a ring with a hole), writing Triangle, gmsh, VTK and SVG files.
# Usage: scripts/demo-mesh.sh CLI [OUTDIR]
set -euo pipefail
cli=${1:-build/quadkit}
out=${2:-out/demo}
root=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"

# One line from the --stats JSON: triangles, the uniform grid's count, the angle range.
summary() {
  sed -E 's/.*"triangles": ([0-9]+),.*"min_angle_deg": ([0-9.]+), "max_angle_deg": ([0-9.]+), "uniform_triangles": ([0-9]+).*/   \1 triangles (a uniform grid needs \4), angles from \2 to \3 degrees/'
}

echo "== mesh: the notes' example, examples/mesh/notes.poly on a 16x16 domain"
"$cli" mesh "$root/examples/mesh/notes.poly" --size 16 -o "$out/mesh-notes" \
  --svg "$out/mesh-notes.svg" --stats | summary
echo "   picture: $out/mesh-notes.svg"
echo "== mesh: examples/mesh/richer.poly (64x64, six components, one hole)"
"$cli" mesh "$root/examples/mesh/richer.poly" -o "$out/mesh-richer" --svg "$out/mesh-richer.svg" \
  --msh "$out/mesh-richer.msh" --vtk "$out/mesh-richer.vtu" --stats | summary
echo "   picture: $out/mesh-richer.svg (also .node/.ele, .msh, .vtu)"
echo "== mesh: examples/mesh/real.poly (real coordinates: the dyadic-lattice mode, markers)"
"$cli" mesh "$root/examples/mesh/real.poly" -o "$out/mesh-real" --svg "$out/mesh-real.svg" \
  --msh "$out/mesh-real.msh" --poly "$out/mesh-real.segments.poly" --stats | summary
echo "   picture: $out/mesh-real.svg (gmsh groups marker_1..marker_4, output segments in .poly)"

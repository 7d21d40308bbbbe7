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

# The general mode (any angles, real coordinates): Iceland from Natural Earth, projected
# to metres at its mean latitude and rounded to 1/16 m, when the shared data is there; a
# small coastline-like polygon with a lake and a pier (an internal segment) otherwise.
general_summary() {
  sed -E 's/.*"triangles": ([0-9]+),.*"min_angle_deg": ([0-9.]+), "max_angle_deg": ([0-9.]+),.*"rounded_coordinates": ([0-9]+).*"exempt_angles": ([0-9]+), "smallest_input_angle_deg": ([0-9.e+-]+).*/   \1 triangles, angles from \2 to \3 degrees, \5 exempt angles (smallest input angle \6), \4 coordinates rounded/'
}
shared=${QK_SHARED_DIR:-$root/../shared}
if [ -f "$shared/data/countries-50m.geojson" ]; then
  echo "== mesh: Iceland (countries-50m.geojson, equirectangular metres, rounded to 1/16 m; general mode)"
  set -- "$shared/data/countries-50m.geojson" --field name=Iceland --project equirect --round 2^-4
  name=mesh-iceland
else
  echo "== mesh: a coastline-like polygon with a lake and a pier (general mode; no ../shared data)"
  printf '%s\n' '12 2 0 0' '0 0 0' '1 5 1.25' '2 30 3' '3 30.5 20' '4 12 27.75' '5 3 18' \
    '6 4.5 9.5' '7 10 8' '8 16 7.5' '9 14 13' '10 22 10' '11 26 15.5' \
    '11 0' '0 0 1' '1 1 2' '2 2 3' '3 3 4' '4 4 5' '5 5 6' '6 6 0' '7 7 8' '8 8 9' '9 9 7' \
    '10 10 11' '1' '0 12.5 9.5' >"$out/coast.poly"
  set -- "$out/coast.poly"
  name=mesh-coast
fi
if "$cli" mesh "$@" --general -o "$out/$name" --svg "$out/$name.svg" --min-angle 20 --stats \
  >"$out/$name.json" 2>"$out/$name.err"; then
  general_summary <"$out/$name.json"
  sed 's/^/   /' "$out/$name.err"
  echo "   picture: $out/$name.svg"
else
  echo "   not meshed: $(cat "$out/$name.err")"
fi

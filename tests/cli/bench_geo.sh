#!/usr/bin/env bash
# Smoke test of quadkit-bench's geodesic kNN on the cities data: quadkit and
# GeographicLib's NearestNeighbor must agree. Skipped (exit 77) without the baselines or
# without $QK_SHARED_DIR/data/cities.csv (ctest sets QK_SHARED_DIR; ../shared by default).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
cities="${QK_SHARED_DIR:-$src/../shared}/data/cities.csv"
if [ ! -f "$cities" ]; then
  echo "SKIPPED: $cities not found (set QK_SHARED_DIR to the directory holding data/cities.csv)"
  exit 77
fi
export QK_SHARED_DIR="${QK_SHARED_DIR:-$src/../shared}"
# shellcheck source=lib/bench.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/bench.bash"
run --op geo-knn --n 5000
for i in quadkit geographiclib; do expect_impl $i geo-knn; done
report

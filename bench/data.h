// Data sets and query sets for quadkit-bench. Everything is seeded: the same command
// gives the same points on every machine.
#ifndef QUADKIT_BENCH_DATA_H
#define QUADKIT_BENCH_DATA_H

#include "bench.h"

#include <string>
#include <vector>

namespace qkb {

// The synthetic sets lie in the unit square and always contain (0, 0) and (1, 1) as
// their first two points, so that every library derives the same root square from the
// bounding box (CGAL centres its root on the box, quadkit puts the corner at the minima:
// on a square box both give [0, 1]^2).
//   uniform     independent uniform points;
//   gauss       a mixture of 64 Gaussians, weights following Zipf's law (1/rank);
//   polyline    points spread evenly along 16 random 32-vertex polylines;
//   degenerate  a third exact duplicates (64 locations), a third collinear (on y = x
//               and y = 1/2), a third on a dyadic integer grid;
//   cities      ../shared/data/cities.csv ($QK_SHARED_DIR/data/cities.csv when that is
//               set) as (lon, lat); empty when the file is absent.
std::vector<Pt> make_dataset(const std::string &name, size_t n, std::string *why_empty);

// The path of a file of the shared data directory: $QK_SHARED_DIR/data/NAME when that
// is set (as for the tests), else ../shared/data as fixed at build time.
std::string shared_data(const std::string &name);

// Query points drawn near the data: a random data point plus a small uniform offset
// (about one inter-point spacing), so clustered sets get clustered queries.
std::vector<Pt> make_queries(const std::vector<Pt> &pts, size_t nq, uint64_t seed);

// Reorder points along the Z-order (Morton) curve of their bounding box.
void morton_sort(std::vector<Pt> &qs);

// Boxes for the collision benchmark: centres uniform in the unit square, half-sides up to
// `hmax` (chosen by the caller so that each box meets a few others).
std::vector<Box> make_boxes(size_t n, double hmax, uint64_t seed);

// Discs and rays for the ray benchmark. Ray origins and directions are float values
// (Embree stores rays in float); discs are doubles.
std::vector<double> make_discs(size_t n, double rmax, uint64_t seed);
std::vector<Ray> make_rays(size_t n, uint64_t seed);

// The meshing domain: [0, U]^2 with a jittered grid of g x g octagons (edges at 0, 45,
// 90 and 135 degrees, integer vertices), counter-clockwise.
std::vector<Ring> make_octagons(unsigned U, unsigned g, uint64_t seed);

} // namespace qkb

#endif

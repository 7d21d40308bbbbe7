// The quadkit side of every comparison, through the public C API only.
#ifndef QUADKIT_BENCH_QUADKIT_SIDE_H
#define QUADKIT_BENCH_QUADKIT_SIDE_H

#include "bench.h"

namespace qkb {

// Leaf capacity used for the point benchmarks (the 16-64 range).
constexpr unsigned kQuadkitCapacity = 32;

std::unique_ptr<PointIndex> make_quadkit(unsigned capacity = kQuadkitCapacity);

// Collision: build the collider over the boxes and report every overlapping pair (the
// pairs on `threads` threads; the build on one).
bool quadkit_collide(const std::vector<Box> &boxes, PairSum &out, unsigned threads = 1);

// For the check against brute force: the same collider's pairs (one thread) that involve
// a marked box, per marked box i: per[i].pairs the boxes it overlaps, per[i].hash the sum
// of their indices (per is resized to boxes.size(); unmarked entries stay zero).
void quadkit_collide_marked(const std::vector<Box> &boxes, const std::vector<char> &marked,
                            std::vector<PairSum> &per);

// The same on a collider kept from call to call: built by the first call, rebuilt over
// the boxes (qk_collider_rebuild, in its kept memory) by every later one.
struct QuadkitBoxes;
QuadkitBoxes *quadkit_boxes_new(unsigned threads = 1);
void quadkit_boxes_collide(QuadkitBoxes *s, const std::vector<Box> &boxes, PairSum &out);
void quadkit_boxes_free(QuadkitBoxes *s);

// Rays: a collider over discs, built once, then first hits.
struct QuadkitDiscs;
QuadkitDiscs *quadkit_discs_build(const std::vector<double> &xyr);
void quadkit_discs_raycast(QuadkitDiscs *s, const std::vector<Ray> &rays, HitSum &out);
// The same rays through qk_collider_raycast_batch on `threads` threads.
void quadkit_discs_raycast_batch(QuadkitDiscs *s, const std::vector<Ray> &rays, unsigned threads,
                                 HitSum &out);
void quadkit_discs_free(QuadkitDiscs *s);

// Balance: a tree over pts in the root [0, 1]^2 with the given capacity and depth cap;
// times qk_tree_balance() alone. The tree before balancing is kept in *keep (freed with
// quadkit_tree_free) when keep is not NULL, to drive the other libraries' refinement.
struct QuadkitTree;
bool quadkit_balance(const std::vector<Pt> &pts, unsigned capacity, unsigned max_depth,
                     BalanceResult &out, QuadkitTree **keep);
bool quadkit_tree_split(double x0, double y0, double side, int depth, void *tree);
void quadkit_tree_free(QuadkitTree *t);

// Build only, for the build benchmark; returns the leaf count and bytes held.
// Build quadkit's tree of the points with the default options but `threads` threads and
// free it; returns the leaf count (the threaded build row of --op build).
size_t quadkit_build_threads(const std::vector<Pt> &pts, unsigned capacity, unsigned threads);
size_t quadkit_build_leaves(const std::vector<Pt> &pts, unsigned capacity, unsigned max_depth,
                            size_t *bytes);

// Meshing through qk_mesh_generate().
bool quadkit_mesh(unsigned U, const std::vector<Ring> &rings, MeshResult &out, std::string *err);
// The dyadic-lattice mode (real coordinates) with a longest-edge bound max_edge.
bool quadkit_mesh_dyadic(const std::vector<Ring> &rings, double max_edge, MeshResult &out,
                         std::string *err);

// The general mode (QK_MESH_GENERAL) with a longest-edge bound (0: none); the time
// includes making the input from the arrays. The mesh's exempt angles (inside input
// angles below 60 degrees) are counted in *exempt when not NULL. min_angle_deg: the
// mode's option (0: its default, the proven 20 degrees).
bool quadkit_mesh_general(const Pslg &in, double max_edge, MeshResult &out, std::string *err,
                          size_t *exempt = nullptr, double min_angle_deg = 0);

// Geodesic kNN through qk_geo_knn().
struct QuadkitGeo;
QuadkitGeo *quadkit_geo_build(const std::vector<Pt> &lonlat);
void quadkit_geo_knn(QuadkitGeo *g, const std::vector<Pt> &qs, int k, std::vector<double> &dist);
void quadkit_geo_free(QuadkitGeo *g);
// qk_geo_distance(): metres on WGS84 (NAN when it fails), for the check against brute force.
double quadkit_geo_distance(Pt a, Pt b);

} // namespace qkb

#endif

// quadkit-bench: shared declarations between the driver (main.cpp) and the baselines.
// Each baseline lives in its own translation unit so that the heavy headers (CGAL above
// all) are compiled once and a missing library only removes its own file from the build.
#ifndef QUADKIT_BENCH_H
#define QUADKIT_BENCH_H

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace qkb {

// Points are two parallel-free arrays of (x, y) doubles, the layout qk_point_t has.
struct Pt {
  double x, y;
};

// The answer to one kNN query: ids and squared distances, nearest first.
struct KnnOut {
  std::vector<uint32_t> ids; // nq * k, QK_NONE-like 0xffffffff where missing
  std::vector<double> d2;    // nq * k
};

// A point index under test. Every implementation answers in doubles; Embree keeps float
// bounds in its BVH but the callbacks measure distances on the double coordinates, so
// its answers are exact too (see base_embree.cpp).
class PointIndex {
public:
  virtual ~PointIndex() = default;
  virtual const char *name() const = 0;
  // Build over pts (borrowed: pts outlives the index).
  virtual void build(const std::vector<Pt> &pts) = 0;
  // k nearest neighbours of each query, one query per call (batch = false) or through
  // the library's own many-query entry point when it has one (batch = true).
  virtual void knn(const std::vector<Pt> &qs, int k, bool batch, int threads, KnnOut &out) = 0;
  virtual bool has_batch() const { return false; }
  virtual bool has_threads() const { return false; }
  // For each query, the number of points within r and the sum of their squared
  // distances (a checksum), accumulated into count / sum.
  virtual void radius(const std::vector<Pt> &qs, double r, uint64_t &count, double &sum) = 0;
  // Points inside each closed box [c - h, c + h]; counts and id checksum.
  virtual void range(const std::vector<Pt> &qs, double h, uint64_t &count, uint64_t &idsum) = 0;
  virtual size_t bytes() const = 0;
};

std::unique_ptr<PointIndex> make_flann();
std::unique_ptr<PointIndex> make_nanoflann();
std::unique_ptr<PointIndex> make_embree_points();
std::unique_ptr<PointIndex> make_cgal_orthtree();

// Boxes for the collision and ray benchmarks.
struct Box {
  double xmin, ymin, xmax, ymax;
};
struct PairSum {
  uint64_t pairs = 0;
  uint64_t hash = 0; // sum over pairs (a < b) of a * 1000003 + b, wrapping
};
struct Ray {
  double ox, oy, dx, dy; // float-representable values, so Embree sees the same rays
};
struct HitSum {
  uint64_t hits = 0;
  uint64_t idsum = 0;
  double tsum = 0;
};

// Embree: all overlapping pairs among boxes (BVH build included in the timing).
void embree_collide(const std::vector<Box> &boxes, PairSum &out);
// The same, on a scene kept from call to call: each call points the geometry at the
// boxes (as many as the first call's) and commits it and the scene again (a full rebuild
// of the BVH in Embree's kept memory) before rtcCollide, as an application that
// rebuilds every frame would.
// refit: the scene dynamic (RTC_SCENE_FLAG_DYNAMIC, RTC_BUILD_QUALITY_LOW: Embree's
// two-level build) and the geometry RTC_BUILD_QUALITY_REFIT, so that each later commit
// refits the first call's BVH to the new boxes instead of building a new one (the moving
// boxes of --op world; the first call builds it).
struct EmbreeBoxes;
EmbreeBoxes *embree_boxes_new(size_t n, bool refit = false);
void embree_boxes_collide(EmbreeBoxes *s, const std::vector<Box> &boxes, PairSum &out);
void embree_boxes_free(EmbreeBoxes *s);
// Embree: first hit of each ray among discs (x, y, r); the BVH is built by
// embree_discs_build and reused.
struct EmbreeDiscs;
EmbreeDiscs *embree_discs_build(const std::vector<double> &xyr);
void embree_discs_raycast(EmbreeDiscs *s, const std::vector<Ray> &rays, HitSum &out);
void embree_discs_free(EmbreeDiscs *s);

// Balance: leaves before / after and the time of the balancing step alone. The
// refinement is described by a callback on (x0, y0, side, depth) of a square of the
// unit root: split or not.
struct BalanceResult {
  size_t leaves_before = 0, leaves_after = 0;
  double seconds = 0;
  size_t unbalanced = 0; // leaves violating 2:1 after balancing, by an independent check
};
using SplitFn = bool (*)(double x0, double y0, double side, int depth, void *ud);
bool cgal_grade(const std::vector<Pt> &pts, int max_depth, int bucket, BalanceResult &out);
bool p4est_balance_run(SplitFn split, void *ud, int max_level, BalanceResult &out);
size_t cgal_orthtree_build_leaves(const std::vector<Pt> &pts, int max_depth, int bucket);
// The same build for the timing alone: the points converted to CGAL's type beforehand
// (cgal_points_new; refine() reorders them, so cgal_points_reset restores the input order
// before each build, untimed), then cgal_orthtree_build: the tree's construction, refine()
// and its destruction, with no count of its leaves.
struct CgalPoints;
CgalPoints *cgal_points_new(const std::vector<Pt> &pts);
void cgal_points_reset(CgalPoints *c, const std::vector<Pt> &pts);
void cgal_orthtree_build(CgalPoints *c, int max_depth, int bucket);
void cgal_points_free(CgalPoints *c);

// Meshing: a domain [0, U]^2 with polygonal components (closed rings of vertices).
struct MeshResult {
  size_t triangles = 0;
  double min_angle_deg = 0;
  double seconds = 0;
};
using Ring = std::vector<Pt>;
bool cgal_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out);
bool gmsh_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out);

// The general mode's inputs: a planar straight-line graph (vertices, segments, hole
// points) whose segments form closed rings (outer rings with sign +1, holes -1), as the
// coastlines and the random polygons of --op mesh are. The domain is the inside of the
// outer rings minus the holes.
struct Pslg {
  std::vector<double> xy;
  std::vector<uint32_t> seg;
  std::vector<double> holes;
  std::vector<std::vector<uint32_t>> rings;
  std::vector<int> ring_sign;
};
// CGAL Mesh_2: constrained Delaunay triangulation of the segments, refined with
// Delaunay_mesh_size_criteria_2(0.125, max_edge), the hole points as seeds of the
// regions left out.
bool cgal_mesh_pslg(const Pslg &in, double max_edge, MeshResult &out);
// gmsh: one plane surface per outer ring with its holes, 2D Delaunay (algorithm 5),
// Mesh.MeshSizeMax = max_edge.
bool gmsh_mesh_pslg(const Pslg &in, double max_edge, MeshResult &out);

// Geodesic kNN (GeographicLib NearestNeighbor over Geodesic::WGS84 distances).
struct GeoIndex;
GeoIndex *geo_build(const std::vector<Pt> &lonlat);
void geo_knn(GeoIndex *g, const std::vector<Pt> &qs, int k, std::vector<double> &dist_out);
void geo_free(GeoIndex *g);

// Moving boxes (--op world): a scene, its motion, and the implementations compared.
struct WorldScene {
  std::vector<Box> boxes;
  std::vector<Pt> vel;
  double side = 0; // boxes bounce inside [0, side]^2
};
WorldScene make_world_scene(const std::string &kind, size_t n, uint64_t seed);
void world_step(WorldScene &s); // one frame of motion
// Queries on a world (--op world-query): segments from (px, py) to (qx, qy), and hits
// (the object's index and the segment's parameter or the distance; id kNoHit: none).
struct Seg {
  double px, py, qx, qy;
};
struct Hit {
  uint32_t id;
  double t;
};
constexpr uint32_t kNoHit = 0xffffffffu;
class WorldImpl {
public:
  virtual ~WorldImpl() = default;
  virtual const char *name() const = 0;
  virtual void init(const std::vector<Box> &boxes) = 0;
  // The boxes' new positions; every overlapping pair of the frame into out.
  virtual void frame(const std::vector<Box> &boxes, PairSum &out) = 0;
  virtual size_t bytes() const = 0; // 0 when the library does not say
  // The part of bytes() that is pair state kept between frames (the last frame's pairs,
  // began / ended), not the index: 0 when there is none or the library does not say.
  virtual size_t pair_bytes() const { return 0; }
  // Seconds of the last frame() spent in the library's own pair search (quadkit:
  // qk_world_update, without the caller's moves and walk of the pairs), by the bench's
  // clock; 0 when not measured.
  virtual double update_seconds() const { return 0; }
  // Queries on the structure as its last frame() left it, answered exactly on that
  // frame's boxes (--op world-query); false when the implementation has no such query.
  // The first object each segment touches (least parameter, then least index), one call
  // a segment or (batch) the library's many-segment call.
  virtual bool first_hits(const std::vector<Box> &, const std::vector<Seg> &, bool,
                          std::vector<Hit> &) {
    return false;
  }
  // For query box i and every object j overlapping it: pairs += 1, hash += i * 1000003 + j.
  virtual bool overlaps(const std::vector<Box> &, const std::vector<Box> &, PairSum &) {
    return false;
  }
  // The nearest object to each point (least distance, then least index).
  virtual bool nearest(const std::vector<Pt> &, bool, std::vector<Hit> &) { return false; }
};
// The exact answers the baselines filter their candidates with (base_world.cpp).
bool seg_meets_box(const Seg &s, const Box &b);
double seg_box_param(const Seg &s, const Box &b);
std::vector<std::unique_ptr<WorldImpl>> make_world_impls();
std::unique_ptr<WorldImpl> make_world_quadkit(unsigned threads); // qk_world on that many threads

// Which baselines this binary was built with.
bool have(const char *what);
bool skipped(const std::string &name); // named in QKB_SKIP

double now_seconds();
double min_angle_of(const std::vector<double> &xy, const std::vector<uint32_t> &tri);

// Polygon layers for `--op region` (base_region.cpp): rings as read from GeoJSON, the
// first ring of each polygon a shell, the others its holes.
struct RegionLayer {
  std::vector<double> xy;
  std::vector<size_t> ring_start, feature_start;
  std::vector<bool> ring_is_shell;
  double box[4];
};
bool region_load(const std::string &path, RegionLayer &L, std::string *why);
struct GeosRegions;
GeosRegions *geos_regions_build(const RegionLayer &L);
void geos_regions_locate(GeosRegions *g, const std::vector<Pt> &pts, std::vector<uint32_t> &out);
void geos_regions_free(GeosRegions *g);
struct S2Regions;
S2Regions *s2_regions_build(const RegionLayer &L);
void s2_regions_locate(S2Regions *s, const std::vector<Pt> &pts, std::vector<uint32_t> &out);
void s2_regions_free(S2Regions *s);
} // namespace qkb

#endif

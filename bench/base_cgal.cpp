// Baselines on CGAL: Orthtree (build by refine(), 2:1 balance by grade()) and Mesh_2
// (refine_Delaunay_mesh_2). Kept in its own translation unit: CGAL's headers take most
// of the benchmark's compile time, and this way they are compiled once.
#include "bench.h"

#ifdef QKB_HAVE_CGAL
#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Delaunay_mesh_face_base_2.h>
#include <CGAL/Delaunay_mesh_size_criteria_2.h>
#include <CGAL/Delaunay_mesher_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Orthtree.h>
#include <CGAL/Orthtree_traits_2.h>
#include <CGAL/Simple_cartesian.h>

#include <cmath>
#include <map>
#include <set>
#include <tuple>

namespace qkb {

namespace {
using SK = CGAL::Simple_cartesian<double>;
using P2 = SK::Point_2;
using Quadtree = CGAL::Orthtree<CGAL::Orthtree_traits_2<SK>, std::vector<P2>>;

size_t count_leaves(Quadtree &t) {
  size_t n = 0;
  for (auto node : t.traverse<CGAL::Orthtrees::Leaves_traversal>()) {
    (void)node;
    n++;
  }
  return n;
}
// An independent 2:1 check of a graded tree: a leaf at depth d violates the rule when a
// square of depth d + 1 adjacent to it across an edge is an internal node (the
// neighbour is then subdivided at least two levels finer). Internal nodes are collected
// as the proper ancestors of the leaves, keyed by (depth, global x, global y).
size_t count_unbalanced(Quadtree &t) {
  std::set<std::tuple<int, uint64_t, uint64_t>> internal;
  std::vector<std::tuple<int, uint64_t, uint64_t>> leaves;
  for (auto node : t.traverse<CGAL::Orthtrees::Leaves_traversal>()) {
    int d = node.depth();
    uint64_t x = node.global_coordinates()[0], y = node.global_coordinates()[1];
    leaves.emplace_back(d, x, y);
    for (int a = d - 1; a >= 0; a--) {
      x >>= 1, y >>= 1;
      if (!internal.emplace(a, x, y).second) break;
    }
  }
  size_t bad = 0;
  for (auto &l : leaves) {
    int d = std::get<0>(l);
    int64_t x = (int64_t)std::get<1>(l) * 2, y = (int64_t)std::get<2>(l) * 2;
    int64_t lim = (int64_t)1 << (d + 1);
    // The two depth-(d+1) squares beyond each edge of the leaf.
    int64_t cand[4][2][2] = {{{x - 1, y}, {x - 1, y + 1}},
                             {{x + 2, y}, {x + 2, y + 1}},
                             {{x, y - 1}, {x + 1, y - 1}},
                             {{x, y + 2}, {x + 1, y + 2}}};
    bool v = false;
    for (auto &side : cand)
      for (auto &c : side)
        if (c[0] >= 0 && c[1] >= 0 && c[0] < lim && c[1] < lim &&
            internal.count({d + 1, (uint64_t)c[0], (uint64_t)c[1]}))
          v = true;
    bad += v;
  }
  return bad;
}

} // namespace

size_t cgal_orthtree_build_leaves(const std::vector<Pt> &pts, int max_depth, int bucket) {
  std::vector<P2> v;
  v.reserve(pts.size());
  for (const Pt &p : pts) v.emplace_back(p.x, p.y);
  // Enlarge ratio 1: the root is the bounding square, as quadkit's default root.
  Quadtree t(v, CGAL::Identity_property_map<P2>(), 1.0);
  t.refine((size_t)max_depth, (size_t)bucket);
  return count_leaves(t);
}

struct CgalPoints {
  std::vector<P2> v;
};

CgalPoints *cgal_points_new(const std::vector<Pt> &pts) {
  CgalPoints *c = new CgalPoints;
  c->v.reserve(pts.size());
  cgal_points_reset(c, pts);
  return c;
}

void cgal_points_reset(CgalPoints *c, const std::vector<Pt> &pts) {
  c->v.clear();
  for (const Pt &p : pts) c->v.emplace_back(p.x, p.y);
}

void cgal_orthtree_build(CgalPoints *c, int max_depth, int bucket) {
  // As cgal_orthtree_build_leaves, on points converted beforehand and without the count.
  Quadtree t(c->v, CGAL::Identity_property_map<P2>(), 1.0);
  t.refine((size_t)max_depth, (size_t)bucket);
}

void cgal_points_free(CgalPoints *c) { delete c; }

bool cgal_grade(const std::vector<Pt> &pts, int max_depth, int bucket, BalanceResult &out) {
  std::vector<P2> v;
  v.reserve(pts.size());
  for (const Pt &p : pts) v.emplace_back(p.x, p.y);
  Quadtree t(v, CGAL::Identity_property_map<P2>(), 1.0);
  t.refine((size_t)max_depth, (size_t)bucket);
  out.leaves_before = count_leaves(t);
  double t0 = now_seconds();
  t.grade();
  out.seconds = now_seconds() - t0;
  out.leaves_after = count_leaves(t);
  out.unbalanced = count_unbalanced(t);
  return true;
}

// The constrained Delaunay triangulation both mesh baselines refine (Mesh_2).
namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_2<K>;
using Fb = CGAL::Delaunay_mesh_face_base_2<K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using CDT = CGAL::Constrained_Delaunay_triangulation_2<K, Tds>;
using Criteria = CGAL::Delaunay_mesh_size_criteria_2<CDT>;
} // namespace

// Count the triangles CGAL's refinement left in the domain and measure their smallest angle.
static void read_mesh(const CDT &cdt, MeshResult &out) {
  std::vector<double> xy;
  std::vector<uint32_t> tri;
  std::map<typename CDT::Vertex_handle, uint32_t> id;
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
    id[v] = (uint32_t)(xy.size() / 2);
    xy.push_back(v->point().x());
    xy.push_back(v->point().y());
  }
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (!f->is_in_domain()) continue;
    for (int i = 0; i < 3; i++) tri.push_back(id[f->vertex(i)]);
  }
  out.triangles = tri.size() / 3;
  out.min_angle_deg = min_angle_of(xy, tri);
}

bool cgal_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out) {
  double t0 = now_seconds();
  CDT cdt;
  std::vector<K::Point_2> square = {{0, 0}, {U, 0}, {U, U}, {0, U}};
  cdt.insert_constraint(square.begin(), square.end(), true);
  for (const Ring &r : rings) {
    std::vector<K::Point_2> ring;
    for (const Pt &p : r) ring.emplace_back(p.x, p.y);
    cdt.insert_constraint(ring.begin(), ring.end(), true);
  }
  // 0.125 is the bound on (sin of the smallest angle)^2 CGAL documents as the one that
  // guarantees termination (about 20.7 degrees).
  CGAL::refine_Delaunay_mesh_2(cdt, Criteria(0.125, max_edge));
  out.seconds = now_seconds() - t0;
  read_mesh(cdt, out);
  return true;
}

bool cgal_mesh_pslg(const Pslg &in, double max_edge, MeshResult &out) {
  double t0 = now_seconds();
  CDT cdt;
  std::vector<CDT::Vertex_handle> vh(in.xy.size() / 2);
  for (size_t i = 0; i < vh.size(); i++)
    vh[i] = cdt.insert(K::Point_2(in.xy[2 * i], in.xy[2 * i + 1]));
  for (size_t s = 0; s < in.seg.size() / 2; s++)
    cdt.insert_constraint(vh[in.seg[2 * s]], vh[in.seg[2 * s + 1]]);
  std::vector<K::Point_2> seeds;
  for (size_t h = 0; h < in.holes.size() / 2; h++)
    seeds.emplace_back(in.holes[2 * h], in.holes[2 * h + 1]);
  // 0.125 bounds (sin of the smallest angle)^2: about 20.7 degrees, CGAL's guarantee.
  CGAL::refine_Delaunay_mesh_2(cdt, seeds.begin(), seeds.end(), Criteria(0.125, max_edge), false);
  out.seconds = now_seconds() - t0;
  read_mesh(cdt, out);
  return true;
}

} // namespace qkb

#else
namespace qkb {
size_t cgal_orthtree_build_leaves(const std::vector<Pt> &, int, int) { return 0; }
struct CgalPoints {};
CgalPoints *cgal_points_new(const std::vector<Pt> &) { return nullptr; }
void cgal_points_reset(CgalPoints *, const std::vector<Pt> &) {}
void cgal_orthtree_build(CgalPoints *, int, int) {}
void cgal_points_free(CgalPoints *) {}
bool cgal_grade(const std::vector<Pt> &, int, int, BalanceResult &) { return false; }
bool cgal_mesh(double, const std::vector<Ring> &, double, MeshResult &) { return false; }
bool cgal_mesh_pslg(const Pslg &, double, MeshResult &) { return false; }
} // namespace qkb
#endif

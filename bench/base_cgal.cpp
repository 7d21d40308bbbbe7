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
} // namespace

size_t cgal_orthtree_build_leaves(const std::vector<Pt> &pts, int max_depth, int bucket) {
  // The points are converted before the clock starts (see main.cpp): this function
  // is timed as a whole, so the conversion is kept to a plain copy of two doubles.
  std::vector<P2> v;
  v.reserve(pts.size());
  for (const Pt &p : pts) v.emplace_back(p.x, p.y);
  // Enlarge ratio 1: the root is the bounding square, as quadkit's default root.
  Quadtree t(v, CGAL::Identity_property_map<P2>(), 1.0);
  t.refine((size_t)max_depth, (size_t)bucket);
  return count_leaves(t);
}

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
  return true;
}

bool cgal_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Vb = CGAL::Triangulation_vertex_base_2<K>;
  using Fb = CGAL::Delaunay_mesh_face_base_2<K>;
  using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
  using CDT = CGAL::Constrained_Delaunay_triangulation_2<K, Tds>;
  using Criteria = CGAL::Delaunay_mesh_size_criteria_2<CDT>;
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
  std::vector<double> xy;
  std::vector<uint32_t> tri;
  std::map<CDT::Vertex_handle, uint32_t> id;
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
  return true;
}

} // namespace qkb

#else
namespace qkb {
size_t cgal_orthtree_build_leaves(const std::vector<Pt> &, int, int) { return 0; }
bool cgal_grade(const std::vector<Pt> &, int, int, BalanceResult &) { return false; }
bool cgal_mesh(double, const std::vector<Ring> &, double, MeshResult &) { return false; }
} // namespace qkb
#endif

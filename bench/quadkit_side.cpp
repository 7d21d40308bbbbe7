// The quadkit side of the comparisons, through the public API (quadkit/quadkit.h).
#include "quadkit_side.h"
#include "parallel.h"

#include "quadkit/quadkit.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

namespace qkb {

static_assert(sizeof(Pt) == sizeof(qk_point_t), "Pt and qk_point_t share a layout");
static_assert(sizeof(Box) == sizeof(qk_box_t), "Box and qk_box_t share a layout");

namespace {

void die(const char *what, qk_status_t st) {
  fprintf(stderr, "quadkit-bench: %s: %s\n", what, qk_strerror(st));
  exit(3);
}

const qk_point_t *as_points(const std::vector<Pt> &v) {
  return reinterpret_cast<const qk_point_t *>(v.data());
}

struct SumUd {
  uint64_t count = 0, idsum = 0;
  double sum = 0;
};

int radius_fn(qk_id_t, qk_point_t, double dist, void *ud) {
  SumUd *s = (SumUd *)ud;
  s->count++;
  s->sum += dist * dist;
  return 0;
}

int range_fn(qk_id_t id, qk_point_t, double, void *ud) {
  SumUd *s = (SumUd *)ud;
  s->count++;
  s->idsum += id;
  return 0;
}

class QuadkitPoints : public PointIndex {
  unsigned capacity;
  qk_tree_t *tree = nullptr;

public:
  explicit QuadkitPoints(unsigned cap) : capacity(cap) {}
  ~QuadkitPoints() override { qk_tree_free(tree); }
  const char *name() const override { return "quadkit"; }
  bool has_batch() const override { return true; }
  bool has_threads() const override { return true; }
  void build(const std::vector<Pt> &pts) override {
    qk_tree_free(tree);
    tree = nullptr;
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = capacity;
    // QKB_HUGE_PAGES=1: the point arrays on transparent huge pages (an A/B of the TLB's
    // share of the query rates; see docs/benchmarks.md).
    if (const char *h = std::getenv("QKB_HUGE_PAGES")) o.huge_pages = std::atoi(h) != 0;
    qk_status_t st = qk_tree_build(as_points(pts), pts.size(), &o, &tree);
    if (st) die("qk_tree_build", st);
  }
  void knn(const std::vector<Pt> &qs, int k, bool batch, int threads, KnnOut &out) override {
    size_t nq = qs.size();
    out.ids.resize(nq * k);
    out.d2.resize(nq * k);
    // The library's answers, copied out by the thread that computed them: no pass over the
    // outputs on one thread (their first touches included), which the threaded rows
    // would otherwise time as a serial part that is the harness's, not the library's.
    std::unique_ptr<qk_neighbor_t[]> buf(new qk_neighbor_t[nq * k]);
    if (batch && threads > 1) {
      // The batch on the library's own threads (the tree's setting), as a caller would
      // run it: one call, which orders the whole batch and shares it out. (Until the
      // twenty-fourth session this row split the batch over the harness's threads, each
      // calling a one-thread batch on its half: that timed this harness's thread starts,
      // not the library's.) The copy below is the same serial pass as the one-thread row's.
      qk_tree_set_threads(tree, (uint32_t)threads);
      qk_status_t st = qk_query_knn_batch(tree, as_points(qs), nq, k, INFINITY, buf.get(), NULL);
      qk_tree_set_threads(tree, 1);
      if (st) die("qk_query_knn_batch", st);
      for (size_t i = 0; i < nq * k; i++) {
        out.ids[i] = buf[i].id;
        out.d2[i] = buf[i].dist * buf[i].dist;
      }
      return;
    }
    parallel_for(nq, threads, [&](size_t lo, size_t hi) {
      if (batch) {
        qk_status_t st =
            qk_query_knn_batch(tree, as_points(qs) + lo, hi - lo, k, INFINITY, &buf[lo * k], NULL);
        if (st) die("qk_query_knn_batch", st);
      } else {
        for (size_t i = lo; i < hi; i++) {
          size_t n = 0;
          qk_point_t q = {qs[i].x, qs[i].y};
          qk_query_knn(tree, q, k, INFINITY, &buf[i * k], &n);
          for (size_t j = n; j < (size_t)k; j++) buf[i * k + j] = {QK_NONE, INFINITY};
        }
      }
      for (size_t i = lo * k; i < hi * k; i++) {
        out.ids[i] = buf[i].id;
        out.d2[i] = buf[i].dist * buf[i].dist;
      }
    });
  }
  void radius(const std::vector<Pt> &qs, double r, uint64_t &count, double &sum) override {
    SumUd s;
    for (const Pt &c : qs) qk_query_radius(tree, {c.x, c.y}, r, radius_fn, &s);
    count += s.count;
    sum += s.sum;
  }
  void range(const std::vector<Pt> &qs, double h, uint64_t &count, uint64_t &idsum) override {
    SumUd s;
    for (const Pt &c : qs) qk_query_range(tree, {c.x - h, c.y - h, c.x + h, c.y + h}, range_fn, &s);
    count += s.count;
    idsum += s.idsum;
  }
  size_t bytes() const override { return qk_tree_memory(tree); }
};

int pair_fn(qk_id_t a, qk_id_t b, void *ud) {
  PairSum *p = (PairSum *)ud;
  p->pairs++;
  p->hash += (uint64_t)a * 1000003u + b;
  return 0;
}

} // namespace

std::unique_ptr<PointIndex> make_quadkit(unsigned capacity) {
  return std::unique_ptr<PointIndex>(new QuadkitPoints(capacity));
}

// The collider's leaf capacity in the benchmarks (the library's default is the book's 1).
static qk_tree_options_t collider_options() {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 8;
  // No huge_pages: the collider advises its large arrays for huge pages whatever the
  // option says, as Embree does over its BVH on Linux (madvise MADV_HUGEPAGE on its
  // 128 MB and 32 MB blocks at 1M discs, seen with strace).
  return o;
}

bool quadkit_collide(const std::vector<Box> &boxes, PairSum &out, unsigned threads) {
  qk_collider_t *c = nullptr;
  qk_tree_options_t o = collider_options();
  o.threads = threads; // the build's phases and the pairs on the same threads
  qk_status_t st = qk_collider_build(nullptr, 0, reinterpret_cast<const qk_box_t *>(boxes.data()),
                                     boxes.size(), &o, &c);
  if (st) die("qk_collider_build", st);
  qk_collider_pairs(c, pair_fn, &out); // no rays: their structures are never made
  qk_collider_free(c);
  return true;
}

namespace {
struct Marked {
  const std::vector<char> *marked;
  std::vector<PairSum> *per;
};
int marked_fn(qk_id_t a, qk_id_t b, void *ud) {
  Marked *m = (Marked *)ud;
  if ((*m->marked)[a]) (*m->per)[a].pairs++, (*m->per)[a].hash += b;
  if ((*m->marked)[b]) (*m->per)[b].pairs++, (*m->per)[b].hash += a;
  return 0;
}
} // namespace

void quadkit_collide_marked(const std::vector<Box> &boxes, const std::vector<char> &marked,
                            std::vector<PairSum> &per) {
  per.assign(boxes.size(), PairSum());
  qk_collider_t *c = nullptr;
  qk_tree_options_t o = collider_options();
  qk_status_t st = qk_collider_build(nullptr, 0, reinterpret_cast<const qk_box_t *>(boxes.data()),
                                     boxes.size(), &o, &c);
  if (st) die("qk_collider_build", st);
  Marked m{&marked, &per};
  qk_collider_pairs(c, marked_fn, &m);
  qk_collider_free(c);
}

struct QuadkitBoxes {
  qk_collider_t *c = nullptr;
  unsigned threads = 1;
};

QuadkitBoxes *quadkit_boxes_new(unsigned threads) {
  QuadkitBoxes *s = new QuadkitBoxes;
  s->threads = threads;
  return s;
}

void quadkit_boxes_collide(QuadkitBoxes *s, const std::vector<Box> &boxes, PairSum &out) {
  const qk_box_t *b = reinterpret_cast<const qk_box_t *>(boxes.data());
  qk_status_t st;
  if (s->c) {
    st = qk_collider_rebuild(s->c, nullptr, 0, b, boxes.size());
  } else {
    qk_tree_options_t o = collider_options();
    o.threads = s->threads;
    st = qk_collider_build(nullptr, 0, b, boxes.size(), &o, &s->c);
  }
  if (st) die("qk_collider_rebuild", st);
  qk_collider_pairs(s->c, pair_fn, &out);
}

void quadkit_boxes_free(QuadkitBoxes *s) {
  if (!s) return;
  qk_collider_free(s->c);
  delete s;
}

struct QuadkitDiscs {
  qk_collider_t *c;
  // The batch's arrays, kept from call to call as a caller casting every frame keeps
  // them: made anew per call, 48 MB at 10^6 rays, they were faulted in (15-20 us a 4 KiB
  // page on this machine) on the calling thread inside the clock.
  std::vector<qk_point_t> o, d;
  std::vector<qk_hit_t> h;
};

QuadkitDiscs *quadkit_discs_build(const std::vector<double> &xyr) {
  std::vector<qk_disc_t> d(xyr.size() / 3);
  for (size_t i = 0; i < d.size(); i++) d[i] = {xyr[3 * i], xyr[3 * i + 1], xyr[3 * i + 2]};
  QuadkitDiscs *s = new QuadkitDiscs{};
  const qk_tree_options_t o = collider_options();
  qk_status_t st = qk_collider_build(d.data(), d.size(), nullptr, 0, &o, &s->c);
  if (st) die("qk_collider_build", st);
  // The ray structures are made on first need; made here they count as the build, as
  // Embree's rtcCommitScene builds its BVH before the first ray.
  st = qk_collider_prepare_rays(s->c);
  if (st) die("qk_collider_prepare_rays", st);
  return s;
}

void quadkit_discs_raycast(QuadkitDiscs *s, const std::vector<Ray> &rays, HitSum &out) {
  for (const Ray &r : rays) {
    qk_hit_t h;
    qk_collider_raycast(s->c, {r.ox, r.oy}, {r.dx, r.dy}, INFINITY, &h);
    if (h.id != QK_NONE) {
      out.hits++;
      out.idsum += h.id;
      out.tsum += h.t;
    }
  }
}

void quadkit_discs_raycast_batch(QuadkitDiscs *s, const std::vector<Ray> &rays, unsigned threads,
                                 HitSum &out) {
  std::vector<qk_point_t> &o = s->o, &d = s->d;
  std::vector<qk_hit_t> &h = s->h;
  o.resize(rays.size()), d.resize(rays.size()), h.resize(rays.size());
  for (size_t i = 0; i < rays.size(); i++)
    o[i] = {rays[i].ox, rays[i].oy}, d[i] = {rays[i].dx, rays[i].dy};
  qk_collider_set_threads(s->c, threads);
  qk_status_t st =
      qk_collider_raycast_batch(s->c, o.data(), d.data(), rays.size(), INFINITY, h.data());
  if (st) die("qk_collider_raycast_batch", st);
  for (const qk_hit_t &x : h) {
    if (x.id != QK_NONE) {
      out.hits++;
      out.idsum += x.id;
      out.tsum += x.t;
    }
  }
}

void quadkit_discs_free(QuadkitDiscs *s) {
  if (!s) return;
  qk_collider_free(s->c);
  delete s;
}

struct QuadkitTree {
  qk_tree_t *t;
};

static qk_tree_t *build_unit(const std::vector<Pt> &pts, unsigned capacity, unsigned max_depth) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = capacity;
  o.max_depth = max_depth;
  o.has_root = 1;
  o.root = {0, 0, 1};
  qk_tree_t *t = nullptr;
  qk_status_t st = qk_tree_build(as_points(pts), pts.size(), &o, &t);
  if (st) die("qk_tree_build", st);
  return t;
}

bool quadkit_balance(const std::vector<Pt> &pts, unsigned capacity, unsigned max_depth,
                     BalanceResult &out, QuadkitTree **keep) {
  qk_tree_t *t = build_unit(pts, capacity, max_depth);
  qk_tree_stats_t s;
  qk_tree_stats(t, &s);
  out.leaves_before = s.leaves;
  if (keep) *keep = new QuadkitTree{build_unit(pts, capacity, max_depth)};
  double t0 = now_seconds();
  qk_status_t st = qk_tree_balance(t);
  out.seconds = now_seconds() - t0;
  if (st) die("qk_tree_balance", st);
  qk_tree_stats(t, &s);
  out.leaves_after = s.leaves;
  qk_tree_free(t);
  return true;
}

bool quadkit_tree_split(double x0, double y0, double side, int depth, void *ud) {
  const qk_tree_t *t = ((QuadkitTree *)ud)->t;
  qk_node_t leaf;
  if (qk_tree_find_leaf(t, {x0 + side / 2, y0 + side / 2}, &leaf)) return false;
  qk_node_info_t info;
  qk_tree_node_info(t, leaf, &info);
  return (int)info.depth > depth;
}

void quadkit_tree_free(QuadkitTree *t) {
  if (!t) return;
  qk_tree_free(t->t);
  delete t;
}

size_t quadkit_build_threads(const std::vector<Pt> &pts, unsigned capacity, unsigned threads) {
  // Like the one-thread row's index (QuadkitPoints::build): free the previous tree, then build.
  // Freeing the new tree at once instead made glibc hand back fresh pages on most calls, so
  // this row paid page faults the one-thread row did not (1.0x two threads over one).
  static qk_tree_t *kept = nullptr; // the last tree; the process exits with it
  qk_tree_free(kept);
  kept = nullptr;
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = capacity;
  o.threads = threads;
  qk_status_t st = qk_tree_build(as_points(pts), pts.size(), &o, &kept);
  if (st) die("qk_tree_build", st);
  qk_tree_stats_t s;
  qk_tree_stats(kept, &s);
  return s.leaves;
}

size_t quadkit_build_leaves(const std::vector<Pt> &pts, unsigned capacity, unsigned max_depth,
                            size_t *bytes) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = capacity;
  o.max_depth = max_depth;
  qk_tree_t *t = nullptr;
  qk_status_t st = qk_tree_build(as_points(pts), pts.size(), &o, &t);
  if (st) die("qk_tree_build", st);
  qk_tree_stats_t s;
  qk_tree_stats(t, &s);
  if (bytes) *bytes = s.memory_bytes;
  qk_tree_free(t);
  return s.leaves;
}

// Timed from the rings as given, as CGAL's and gmsh's calls are (base_cgal.cpp and
// base_gmsh.cpp time their own conversion and insertion of the rings): the arrays made from
// the rings, qk_poly_from_arrays and qk_mesh_generate (the clock used to start after
// qk_poly_from_arrays, which the general mode's times include, and the others' theirs).
static bool quadkit_mesh_opts(const std::vector<Ring> &rings, const qk_mesh_options_t &o,
                              MeshResult &out, std::string *err) {
  double t0 = now_seconds();
  std::vector<double> xy;
  std::vector<uint32_t> seg;
  for (const Ring &r : rings) {
    uint32_t base = (uint32_t)(xy.size() / 2);
    for (size_t i = 0; i < r.size(); i++) {
      xy.push_back(r[i].x);
      xy.push_back(r[i].y);
      seg.push_back(base + (uint32_t)i);
      seg.push_back(base + (uint32_t)((i + 1) % r.size()));
    }
  }
  qk_poly_t *poly = nullptr;
  qk_mesh_error_t e;
  qk_status_t st = qk_poly_from_arrays(xy.data(), xy.size() / 2, seg.data(), seg.size() / 2,
                                       nullptr, 0, nullptr, &poly, &e);
  if (st) {
    if (err) *err = std::string("qk_poly_from_arrays: ") + e.message;
    return false;
  }
  qk_mesh_t *m = nullptr;
  st = qk_mesh_generate(poly, &o, &m, &e);
  out.seconds = now_seconds() - t0;
  qk_poly_free(poly);
  if (st) {
    if (err) *err = std::string("qk_mesh_generate: ") + qk_strerror(st) + ": " + e.message;
    return false;
  }
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  out.triangles = s.triangles;
  out.min_angle_deg = s.min_angle_deg;
  qk_mesh_free(m);
  return true;
}

bool quadkit_mesh(unsigned U, const std::vector<Ring> &rings, MeshResult &out, std::string *err) {
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = U;
  return quadkit_mesh_opts(rings, o, out, err);
}

bool quadkit_mesh_dyadic(const std::vector<Ring> &rings, double max_edge, MeshResult &out,
                         std::string *err) {
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_DYADIC;
  o.max_size = max_edge;
  return quadkit_mesh_opts(rings, o, out, err);
}

bool quadkit_mesh_general(const Pslg &in, double max_edge, MeshResult &out, std::string *err,
                          size_t *exempt, double min_angle_deg) {
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_GENERAL;
  o.max_size = max_edge;
  o.min_angle_deg = min_angle_deg;
  double t0 = now_seconds();
  qk_poly_t *poly = nullptr;
  qk_mesh_error_t e;
  qk_status_t st =
      qk_poly_from_arrays(in.xy.data(), in.xy.size() / 2, in.seg.data(), in.seg.size() / 2,
                          in.holes.data(), in.holes.size() / 2, nullptr, &poly, &e);
  qk_mesh_t *m = nullptr;
  if (!st) st = qk_mesh_generate(poly, &o, &m, &e);
  out.seconds = now_seconds() - t0;
  qk_poly_free(poly);
  if (st) {
    if (err) *err = std::string(qk_strerror(st)) + ": " + e.message;
    return false;
  }
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  out.triangles = s.triangles;
  out.min_angle_deg = s.min_angle_deg;
  if (exempt) *exempt = s.exempt_angles;
  qk_mesh_free(m);
  return true;
}

struct QuadkitGeo {
  qk_geo_t *g;
};

QuadkitGeo *quadkit_geo_build(const std::vector<Pt> &lonlat) {
  QuadkitGeo *g = new QuadkitGeo{nullptr};
  qk_status_t st = qk_geo_build(as_points(lonlat), lonlat.size(), nullptr, &g->g);
  if (st) {
    delete g;
    return nullptr;
  }
  return g;
}

void quadkit_geo_knn(QuadkitGeo *g, const std::vector<Pt> &qs, int k, std::vector<double> &dist) {
  dist.assign(qs.size() * k, INFINITY);
  std::vector<qk_neighbor_t> buf(k);
  for (size_t i = 0; i < qs.size(); i++) {
    size_t n = 0;
    qk_geo_knn(g->g, {qs[i].x, qs[i].y}, k, INFINITY, buf.data(), &n);
    for (size_t j = 0; j < n; j++) dist[i * k + j] = buf[j].dist;
  }
}

void quadkit_geo_free(QuadkitGeo *g) {
  if (!g) return;
  qk_geo_free(g->g);
  delete g;
}

double quadkit_geo_distance(Pt a, Pt b) {
  double m;
  return qk_geo_distance({a.x, a.y}, {b.x, b.y}, &m) ? NAN : m;
}

} // namespace qkb

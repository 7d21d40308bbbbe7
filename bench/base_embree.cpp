// Baselines on Embree 3: rtcPointQuery (kNN with a radius-shrinking callback, radius and
// box queries), rtcCollide (all overlapping pairs) and rtcIntersect1 (first hit), all on
// user geometry in the z = 0 plane.
//
// Embree's BVH holds float boxes. Every box handed to it is rounded outwards, query
// radii are widened by the float rounding of the query point, and the callbacks measure
// on the original doubles, so the answers are the exact double-precision answers the
// other implementations give; only the pruning runs in float.
#include "bench.h"
#include "parallel.h"

#ifdef QKB_HAVE_EMBREE
#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace qkb {

namespace {

RTCDevice device_for(int threads) {
  static RTCDevice dev[3] = {nullptr, nullptr, nullptr};
  int t = threads >= 2 ? 2 : 1;
  if (!dev[t]) {
    char cfg[32];
    snprintf(cfg, sizeof cfg, "threads=%d", t);
    dev[t] = rtcNewDevice(cfg);
    if (!dev[t]) {
      fprintf(stderr, "quadkit-bench: rtcNewDevice failed\n");
      exit(3);
    }
  }
  return dev[t];
}

inline float down(double v) {
  float f = (float)v;
  return (double)f > v ? std::nextafter(f, -INFINITY) : f;
}
inline float up(double v) {
  float f = (float)v;
  return (double)f < v ? std::nextafter(f, INFINITY) : f;
}

// ---- points -------------------------------------------------------------------------

struct PointGeom {
  const std::vector<Pt> *pts;
};

void point_bounds(const RTCBoundsFunctionArguments *a) {
  const Pt &p = (*((const PointGeom *)a->geometryUserPtr)->pts)[a->primID];
  RTCBounds *b = a->bounds_o;
  b->lower_x = down(p.x);
  b->lower_y = down(p.y);
  b->upper_x = up(p.x);
  b->upper_y = up(p.y);
  b->lower_z = b->upper_z = 0;
}

void no_intersect(const RTCIntersectFunctionNArguments *) {}
void no_occluded(const RTCOccludedFunctionNArguments *) {}

// The current kNN query: its k best so far, sorted ascending by (d2, id).
struct KnnState {
  const std::vector<Pt> *pts;
  double qx, qy, slack;
  int k, n;
  double d2[64];
  uint32_t id[64];
};

bool knn_cb(RTCPointQueryFunctionArguments *a) {
  KnnState *s = (KnnState *)a->userPtr;
  const Pt &p = (*s->pts)[a->primID];
  double dx = p.x - s->qx, dy = p.y - s->qy, d2 = dx * dx + dy * dy;
  uint32_t id = a->primID;
  if (s->n == s->k && (d2 > s->d2[s->n - 1] || (d2 == s->d2[s->n - 1] && id > s->id[s->n - 1])))
    return false;
  int i = s->n < s->k ? s->n++ : s->n - 1;
  while (i > 0 && (s->d2[i - 1] > d2 || (s->d2[i - 1] == d2 && s->id[i - 1] > id))) {
    s->d2[i] = s->d2[i - 1];
    s->id[i] = s->id[i - 1];
    i--;
  }
  s->d2[i] = d2;
  s->id[i] = id;
  if (s->n == s->k) {
    float r = up((std::sqrt(s->d2[s->n - 1]) + s->slack) * (1 + 1e-6));
    if (r < a->query->radius) {
      a->query->radius = r;
      return true;
    }
  }
  return false;
}

struct SumState {
  const std::vector<Pt> *pts;
  double qx, qy, r2, xmin, ymin, xmax, ymax;
  uint64_t count, idsum;
  double sum;
};

bool radius_cb(RTCPointQueryFunctionArguments *a) {
  SumState *s = (SumState *)a->userPtr;
  const Pt &p = (*s->pts)[a->primID];
  double dx = p.x - s->qx, dy = p.y - s->qy, d2 = dx * dx + dy * dy;
  if (d2 <= s->r2) {
    s->count++;
    s->sum += d2;
  }
  return false;
}

bool box_cb(RTCPointQueryFunctionArguments *a) {
  SumState *s = (SumState *)a->userPtr;
  const Pt &p = (*s->pts)[a->primID];
  if (p.x >= s->xmin && p.x <= s->xmax && p.y >= s->ymin && p.y <= s->ymax) {
    s->count++;
    s->idsum += a->primID;
  }
  return false;
}

// Float rounding of a query point: how far its float copy may be from the double.
inline double slack_of(double x, double y) {
  return 2.0 * std::max(std::fabs(x), std::fabs(y)) * FLT_EPSILON + FLT_MIN;
}

class EmbreePoints : public PointIndex {
  RTCScene scene = nullptr;
  PointGeom geom{nullptr};

public:
  ~EmbreePoints() override {
    if (scene) rtcReleaseScene(scene);
  }
  const char *name() const override { return "embree"; }
  bool has_threads() const override { return true; }
  void build(const std::vector<Pt> &pts) override {
    if (scene) rtcReleaseScene(scene);
    RTCDevice dev = device_for(1);
    geom.pts = &pts;
    scene = rtcNewScene(dev);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, (unsigned)pts.size());
    rtcSetGeometryUserData(g, &geom);
    rtcSetGeometryBoundsFunction(g, point_bounds, nullptr);
    rtcSetGeometryIntersectFunction(g, no_intersect);
    rtcSetGeometryOccludedFunction(g, no_occluded);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene);
  }
  void knn(const std::vector<Pt> &qs, int k, bool, int threads, KnnOut &out) override {
    out.ids.assign(qs.size() * k, 0xffffffffu);
    out.d2.assign(qs.size() * k, INFINITY);
    parallel_for(qs.size(), threads, [&](size_t lo, size_t hi) {
      KnnState s;
      s.pts = geom.pts;
      s.k = k;
      for (size_t i = lo; i < hi; i++) {
        s.qx = qs[i].x;
        s.qy = qs[i].y;
        s.slack = slack_of(s.qx, s.qy);
        s.n = 0;
        RTCPointQuery q;
        q.x = (float)s.qx;
        q.y = (float)s.qy;
        q.z = 0;
        q.time = 0;
        q.radius = INFINITY;
        RTCPointQueryContext ctx;
        rtcInitPointQueryContext(&ctx);
        rtcPointQuery(scene, &q, &ctx, knn_cb, &s);
        for (int j = 0; j < s.n; j++) {
          out.ids[i * k + j] = s.id[j];
          out.d2[i * k + j] = s.d2[j];
        }
      }
    });
  }
  void radius(const std::vector<Pt> &qs, double r, uint64_t &count, double &sum) override {
    for (const Pt &c : qs) {
      SumState s{geom.pts, c.x, c.y, r * r, 0, 0, 0, 0, 0, 0, 0};
      RTCPointQuery q;
      q.x = (float)c.x;
      q.y = (float)c.y;
      q.z = q.time = 0;
      q.radius = up((r + slack_of(c.x, c.y)) * (1 + 1e-6));
      RTCPointQueryContext ctx;
      rtcInitPointQueryContext(&ctx);
      rtcPointQuery(scene, &q, &ctx, radius_cb, &s);
      count += s.count;
      sum += s.sum;
    }
  }
  void range(const std::vector<Pt> &qs, double h, uint64_t &count, uint64_t &idsum) override {
    for (const Pt &c : qs) {
      SumState s{geom.pts, c.x, c.y, 0, c.x - h, c.y - h, c.x + h, c.y + h, 0, 0, 0};
      RTCPointQuery q;
      q.x = (float)c.x;
      q.y = (float)c.y;
      q.z = q.time = 0;
      q.radius = up((h * std::sqrt(2.0) + slack_of(c.x, c.y)) * (1 + 1e-6));
      RTCPointQueryContext ctx;
      rtcInitPointQueryContext(&ctx);
      rtcPointQuery(scene, &q, &ctx, box_cb, &s);
      count += s.count;
      idsum += s.idsum;
    }
  }
  size_t bytes() const override {
    // Embree does not report its BVH size; count the caller's coordinates only.
    return geom.pts->size() * sizeof(Pt);
  }
};

// ---- boxes: collision ---------------------------------------------------------------

struct BoxGeom {
  const std::vector<Box> *boxes;
  std::atomic<uint64_t> pairs{0}, hash{0};
};

void box_bounds(const RTCBoundsFunctionArguments *a) {
  const Box &b = (*((const BoxGeom *)a->geometryUserPtr)->boxes)[a->primID];
  RTCBounds *o = a->bounds_o;
  o->lower_x = down(b.xmin);
  o->lower_y = down(b.ymin);
  o->upper_x = up(b.xmax);
  o->upper_y = up(b.ymax);
  o->lower_z = o->upper_z = 0;
}

void collide_cb(void *user, RTCCollision *c, unsigned n) {
  BoxGeom *g = (BoxGeom *)user;
  const std::vector<Box> &bx = *g->boxes;
  uint64_t pairs = 0, hash = 0;
  for (unsigned i = 0; i < n; i++) {
    uint32_t a = c[i].primID0, b = c[i].primID1;
    // A scene collided with itself reports every pair in both orders (and an item
    // with itself): keep a < b only.
    if (a >= b) continue;
    const Box &p = bx[a], &q = bx[b];
    if (p.xmin <= q.xmax && q.xmin <= p.xmax && p.ymin <= q.ymax && q.ymin <= p.ymax) {
      pairs++;
      hash += (uint64_t)a * 1000003u + b;
    }
  }
  g->pairs += pairs;
  g->hash += hash;
}

// ---- discs: ray casting -------------------------------------------------------------

struct DiscGeom {
  const std::vector<double> *xyr;
};

void disc_bounds(const RTCBoundsFunctionArguments *a) {
  const double *d = &(*((const DiscGeom *)a->geometryUserPtr)->xyr)[3 * a->primID];
  RTCBounds *o = a->bounds_o;
  o->lower_x = down(d[0] - d[2]);
  o->lower_y = down(d[1] - d[2]);
  o->upper_x = up(d[0] + d[2]);
  o->upper_y = up(d[1] + d[2]);
  o->lower_z = -1;
  o->upper_z = 1;
}

// The context of one ray: Embree passes it to the callback; it keeps the best hit in
// double precision.
struct RayCtx {
  RTCIntersectContext ctx;
  double ox, oy, dx, dy;
  double t;
  uint32_t id;
};

// Smallest t >= 0 at which origin + t * dir touches the closed disc, or -1.
inline double ray_disc(double ox, double oy, double dx, double dy, const double *d) {
  double fx = ox - d[0], fy = oy - d[1];
  double c = fx * fx + fy * fy - d[2] * d[2];
  if (c <= 0) return 0;
  double a = dx * dx + dy * dy, b = fx * dx + fy * dy;
  if (b >= 0 || a == 0) return -1;
  double disc = b * b - a * c;
  if (disc < 0) return -1;
  return (-b - std::sqrt(disc)) / a;
}

void disc_intersect(const RTCIntersectFunctionNArguments *a) {
  if (!a->valid[0]) return;
  RayCtx *rc = (RayCtx *)a->context;
  const double *d = &(*((const DiscGeom *)a->geometryUserPtr)->xyr)[3 * a->primID];
  double t = ray_disc(rc->ox, rc->oy, rc->dx, rc->dy, d);
  if (t < 0) return;
  if (t < rc->t || (t == rc->t && a->primID < rc->id)) {
    rc->t = t;
    rc->id = a->primID;
    RTCRayN *ray = RTCRayHitN_RayN(a->rayhit, a->N);
    RTCHitN *hit = RTCRayHitN_HitN(a->rayhit, a->N);
    // Keep traversing everything that may still hold an equal or earlier hit.
    RTCRayN_tfar(ray, a->N, 0) = up(t * (1 + 1e-6) + 1e-30);
    RTCHitN_primID(hit, a->N, 0) = a->primID;
    RTCHitN_geomID(hit, a->N, 0) = a->geomID;
  }
}

} // namespace

struct EmbreeDiscs {
  RTCScene scene;
  DiscGeom geom;
};

EmbreeDiscs *embree_discs_build(const std::vector<double> &xyr) {
  RTCDevice dev = device_for(1);
  EmbreeDiscs *s = new EmbreeDiscs;
  s->geom.xyr = &xyr;
  s->scene = rtcNewScene(dev);
  rtcSetSceneFlags(s->scene, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(g, (unsigned)(xyr.size() / 3));
  rtcSetGeometryUserData(g, &s->geom);
  rtcSetGeometryBoundsFunction(g, disc_bounds, nullptr);
  rtcSetGeometryIntersectFunction(g, disc_intersect);
  rtcSetGeometryOccludedFunction(g, no_occluded);
  rtcCommitGeometry(g);
  rtcAttachGeometry(s->scene, g);
  rtcReleaseGeometry(g);
  rtcCommitScene(s->scene);
  return s;
}

void embree_discs_raycast(EmbreeDiscs *s, const std::vector<Ray> &rays, HitSum &out) {
  for (const Ray &r : rays) {
    RayCtx rc;
    rtcInitIntersectContext(&rc.ctx);
    rc.ox = r.ox;
    rc.oy = r.oy;
    rc.dx = r.dx;
    rc.dy = r.dy;
    rc.t = INFINITY;
    rc.id = 0xffffffffu;
    RTCRayHit rh;
    rh.ray.org_x = (float)r.ox;
    rh.ray.org_y = (float)r.oy;
    rh.ray.org_z = 0;
    rh.ray.dir_x = (float)r.dx;
    rh.ray.dir_y = (float)r.dy;
    rh.ray.dir_z = 0;
    rh.ray.tnear = 0;
    rh.ray.tfar = INFINITY;
    rh.ray.time = 0;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(s->scene, &rc.ctx, &rh);
    if (rc.id != 0xffffffffu) {
      out.hits++;
      out.idsum += rc.id;
      out.tsum += rc.t;
    }
  }
}

void embree_discs_free(EmbreeDiscs *s) {
  if (!s) return;
  rtcReleaseScene(s->scene);
  delete s;
}

void embree_collide(const std::vector<Box> &boxes, PairSum &out) {
  RTCDevice dev = device_for(1);
  BoxGeom geom;
  geom.boxes = &boxes;
  RTCScene scene = rtcNewScene(dev);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(g, (unsigned)boxes.size());
  rtcSetGeometryUserData(g, &geom);
  rtcSetGeometryBoundsFunction(g, box_bounds, nullptr);
  rtcSetGeometryIntersectFunction(g, no_intersect);
  rtcSetGeometryOccludedFunction(g, no_occluded);
  rtcCommitGeometry(g);
  rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
  rtcCommitScene(scene);
  rtcCollide(scene, scene, collide_cb, &geom);
  rtcReleaseScene(scene);
  out.pairs = geom.pairs;
  out.hash = geom.hash;
}

struct EmbreeBoxes {
  RTCScene scene;
  RTCGeometry g;
  BoxGeom geom;
};

EmbreeBoxes *embree_boxes_new(size_t n, bool refit) {
  RTCDevice dev = device_for(1);
  EmbreeBoxes *s = new EmbreeBoxes;
  s->geom.boxes = nullptr;
  s->scene = rtcNewScene(dev);
  rtcSetSceneFlags(s->scene, refit ? (RTCSceneFlags)(RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_DYNAMIC)
                                   : RTC_SCENE_FLAG_ROBUST);
  // (Embree 3.13.5 refits only so: without the geometry's quality a dynamic scene's commit
  // builds anew, and without the dynamic scene the geometry's quality is ignored. Seen on the
  // order of rtcCollide's candidate pairs, which a refitted BVH keeps from the first build
  // and a rebuilt one gives as a fresh scene over the same boxes does.)
  if (refit) rtcSetSceneBuildQuality(s->scene, RTC_BUILD_QUALITY_LOW);
  s->g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
  if (refit) rtcSetGeometryBuildQuality(s->g, RTC_BUILD_QUALITY_REFIT);
  rtcSetGeometryUserPrimitiveCount(s->g, (unsigned)n);
  rtcSetGeometryUserData(s->g, &s->geom);
  rtcSetGeometryBoundsFunction(s->g, box_bounds, nullptr);
  rtcSetGeometryIntersectFunction(s->g, no_intersect);
  rtcSetGeometryOccludedFunction(s->g, no_occluded);
  rtcAttachGeometry(s->scene, s->g);
  return s;
}

void embree_boxes_collide(EmbreeBoxes *s, const std::vector<Box> &boxes, PairSum &out) {
  // The geometry committed again counts as modified: the scene's commit rebuilds the BVH
  // (run_collide_reused checks that it does, with other boxes before), or refits it when
  // made with refit (--op world's embree-refit, checked frame by frame).
  s->geom.boxes = &boxes;
  rtcCommitGeometry(s->g);
  rtcCommitScene(s->scene);
  s->geom.pairs = 0;
  s->geom.hash = 0;
  rtcCollide(s->scene, s->scene, collide_cb, &s->geom);
  out.pairs = s->geom.pairs;
  out.hash = s->geom.hash;
}

void embree_boxes_free(EmbreeBoxes *s) {
  if (!s) return;
  rtcReleaseGeometry(s->g);
  rtcReleaseScene(s->scene);
  delete s;
}

std::unique_ptr<PointIndex> make_embree_points() {
  return std::unique_ptr<PointIndex>(new EmbreePoints);
}

} // namespace qkb

#else
namespace qkb {
std::unique_ptr<PointIndex> make_embree_points() { return nullptr; }
void embree_collide(const std::vector<Box> &, PairSum &) {}
struct EmbreeBoxes {};
EmbreeBoxes *embree_boxes_new(size_t, bool) { return nullptr; }
void embree_boxes_collide(EmbreeBoxes *, const std::vector<Box> &, PairSum &) {}
void embree_boxes_free(EmbreeBoxes *) {}
struct EmbreeDiscs {};
EmbreeDiscs *embree_discs_build(const std::vector<double> &) { return nullptr; }
void embree_discs_raycast(EmbreeDiscs *, const std::vector<Ray> &, HitSum &) {}
void embree_discs_free(EmbreeDiscs *) {}
} // namespace qkb
#endif

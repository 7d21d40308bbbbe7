// Polygon point location baselines for `quadkit-bench --op region`: GEOS's C API (an
// STRtree of prepared geometries, GEOSPreparedContains) and S2 (MutableS2ShapeIndex of
// S2LaxPolygonShape, S2ContainsPointQuery), on the rings of a GeoJSON layer read here
// with json-c, so that every implementation gets the same rings. Built only when the
// libraries are found (QKB_HAVE_GEOS / QKB_HAVE_S2); the layer loader needs json-c.
#include "bench.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#ifdef QKB_HAVE_JSONC
#include <json.h>
#endif
#ifdef QKB_HAVE_GEOS
#include <geos_c.h>
#endif
#ifdef QKB_HAVE_S2
#include <s2/mutable_s2shape_index.h>
#include <s2/s2contains_point_query.h>
#include <s2/s2lax_polygon_shape.h>
#include <s2/s2latlng.h>
#endif

namespace qkb {

#ifdef QKB_HAVE_JSONC
static void add_polygon(json_object *rings, RegionLayer &L) {
  for (size_t k = 0, nk = json_object_array_length(rings); k < nk; k++) {
    json_object *r = json_object_array_get_idx(rings, k);
    size_t n = json_object_array_length(r);
    for (size_t i = 0; i < n; i++) {
      json_object *p = json_object_array_get_idx(r, i);
      L.xy.push_back(json_object_get_double(json_object_array_get_idx(p, 0)));
      L.xy.push_back(json_object_get_double(json_object_array_get_idx(p, 1)));
    }
    L.ring_start.push_back(L.xy.size() / 2);
    L.ring_is_shell.push_back(k == 0);
  }
}
#endif

bool region_load(const std::string &path, RegionLayer &L, std::string *why) {
#ifdef QKB_HAVE_JSONC
  json_object *root = json_object_from_file(path.c_str());
  if (!root) {
    if (why) *why = "cannot read " + path;
    return false;
  }
  L = RegionLayer();
  L.ring_start.push_back(0);
  L.feature_start.push_back(0);
  json_object *feats;
  if (json_object_object_get_ex(root, "features", &feats))
    for (size_t f = 0, nf = json_object_array_length(feats); f < nf; f++) {
      json_object *g = nullptr, *t, *c;
      json_object_object_get_ex(json_object_array_get_idx(feats, f), "geometry", &g);
      if (g && json_object_object_get_ex(g, "type", &t) &&
          json_object_object_get_ex(g, "coordinates", &c)) {
        std::string ty = json_object_get_string(t);
        if (ty == "Polygon") add_polygon(c, L);
        if (ty == "MultiPolygon")
          for (size_t i = 0, n = json_object_array_length(c); i < n; i++)
            add_polygon(json_object_array_get_idx(c, i), L);
      }
      L.feature_start.push_back(L.ring_start.size() - 1);
    }
  json_object_put(root);
  L.box[0] = L.box[1] = INFINITY;
  L.box[2] = L.box[3] = -INFINITY;
  for (size_t i = 0; i < L.xy.size(); i += 2) {
    L.box[0] = std::min(L.box[0], L.xy[i]), L.box[2] = std::max(L.box[2], L.xy[i]);
    L.box[1] = std::min(L.box[1], L.xy[i + 1]), L.box[3] = std::max(L.box[3], L.xy[i + 1]);
  }
  return true;
#else
  (void)path, (void)L;
  if (why) *why = "built without json-c";
  return false;
#endif
}

// ---- GEOS ------------------------------------------------------------------------------

#ifdef QKB_HAVE_GEOS
struct GeosRegions {
  GEOSContextHandle_t h;
  std::vector<GEOSGeometry *> geoms;
  std::vector<const GEOSPreparedGeometry *> prep;
  std::vector<uint32_t> ids; // tree items point here
  GEOSSTRtree *tree;
};

static GEOSGeometry *ring_geom(GEOSContextHandle_t h, const RegionLayer &L, size_t r) {
  size_t s = L.ring_start[r], e = L.ring_start[r + 1];
  GEOSCoordSequence *cs = GEOSCoordSeq_copyFromBuffer_r(h, &L.xy[2 * s], e - s, 0, 0);
  return GEOSGeom_createLinearRing_r(h, cs);
}

void geos_regions_locate(GeosRegions *g, const std::vector<Pt> &pts, std::vector<uint32_t> &out);

GeosRegions *geos_regions_build(const RegionLayer &L) {
  auto *g = new GeosRegions;
  g->h = GEOS_init_r();
  size_t nf = L.feature_start.size() - 1;
  g->ids.resize(nf);
  g->tree = GEOSSTRtree_create_r(g->h, 10);
  for (size_t f = 0; f < nf; f++) {
    std::vector<GEOSGeometry *> polys;
    for (size_t r = L.feature_start[f]; r < L.feature_start[f + 1];) {
      GEOSGeometry *shell = ring_geom(g->h, L, r++);
      std::vector<GEOSGeometry *> holes;
      while (r < L.feature_start[f + 1] && !L.ring_is_shell[r])
        holes.push_back(ring_geom(g->h, L, r++));
      polys.push_back(GEOSGeom_createPolygon_r(g->h, shell, holes.data(), (unsigned)holes.size()));
    }
    GEOSGeometry *geom =
        GEOSGeom_createCollection_r(g->h, GEOS_MULTIPOLYGON, polys.data(), (unsigned)polys.size());
    g->geoms.push_back(geom);
    g->prep.push_back(GEOSPrepare_r(g->h, geom));
    g->ids[f] = (uint32_t)f;
    if (!polys.empty()) GEOSSTRtree_insert_r(g->h, g->tree, geom, &g->ids[f]);
  }
  // The tree builds on its first query (GEOSSTRtree_build is GEOS 3.12+): make one.
  std::vector<uint32_t> none;
  geos_regions_locate(g, {Pt{L.box[0], L.box[1]}}, none);
  return g;
}

struct GeosQ {
  GeosRegions *g;
  const GEOSGeometry *pt;
  uint32_t best;
};

static void geos_visit(void *item, void *ud) {
  auto *q = (GeosQ *)ud;
  uint32_t f = *(uint32_t *)item;
  if (f < q->best && GEOSPreparedContains_r(q->g->h, q->g->prep[f], q->pt) == 1) q->best = f;
}

void geos_regions_locate(GeosRegions *g, const std::vector<Pt> &pts, std::vector<uint32_t> &out) {
  out.resize(pts.size());
  for (size_t i = 0; i < pts.size(); i++) {
    GEOSGeometry *p = GEOSGeom_createPointFromXY_r(g->h, pts[i].x, pts[i].y);
    GeosQ q{g, p, UINT32_MAX};
    GEOSSTRtree_query_r(g->h, g->tree, p, geos_visit, &q);
    GEOSGeom_destroy_r(g->h, p);
    out[i] = q.best;
  }
}

void geos_regions_free(GeosRegions *g) {
  if (!g) return;
  GEOSSTRtree_destroy_r(g->h, g->tree);
  for (auto p : g->prep) GEOSPreparedGeom_destroy_r(g->h, p);
  for (auto x : g->geoms) GEOSGeom_destroy_r(g->h, x);
  GEOS_finish_r(g->h);
  delete g;
}
#else
struct GeosRegions {};
GeosRegions *geos_regions_build(const RegionLayer &) { return nullptr; }
void geos_regions_locate(GeosRegions *, const std::vector<Pt> &, std::vector<uint32_t> &) {}
void geos_regions_free(GeosRegions *) {}
#endif

// ---- S2 --------------------------------------------------------------------------------

#ifdef QKB_HAVE_S2
struct S2Regions {
  MutableS2ShapeIndex index;
  std::vector<uint32_t> feature_of; // shape id -> feature
};

S2Regions *s2_regions_build(const RegionLayer &L) {
  auto *s = new S2Regions;
  size_t nf = L.feature_start.size() - 1;
  for (size_t f = 0; f < nf; f++) {
    std::vector<S2LaxPolygonShape::Loop> loops;
    for (size_t r = L.feature_start[f]; r < L.feature_start[f + 1]; r++) {
      size_t a = L.ring_start[r], e = L.ring_start[r + 1] - 1; // drop the closing vertex
      // S2 wants shells counter-clockwise and holes clockwise (in lon/lat, as seen
      // from outside the sphere); the input may have either winding.
      double area2 = 0;
      for (size_t i = a; i < e; i++)
        area2 += L.xy[2 * i] * L.xy[2 * i + 3] - L.xy[2 * i + 2] * L.xy[2 * i + 1];
      bool ccw = area2 > 0, want = L.ring_is_shell[r];
      S2LaxPolygonShape::Loop loop;
      for (size_t i = a; i < e; i++) {
        size_t j = ccw == want ? i : a + (e - 1 - i);
        loop.push_back(S2LatLng::FromDegrees(L.xy[2 * j + 1], L.xy[2 * j]).ToPoint());
      }
      loops.push_back(std::move(loop));
    }
    if (loops.empty()) continue;
    s->index.Add(std::make_unique<S2LaxPolygonShape>(loops));
    s->feature_of.push_back((uint32_t)f);
  }
  s->index.ForceBuild();
  return s;
}

void s2_regions_locate(S2Regions *s, const std::vector<Pt> &pts, std::vector<uint32_t> &out) {
  out.resize(pts.size());
  auto q = MakeS2ContainsPointQuery(&s->index);
  for (size_t i = 0; i < pts.size(); i++) {
    uint32_t best = UINT32_MAX;
    q.VisitContainingShapes(S2LatLng::FromDegrees(pts[i].y, pts[i].x).ToPoint(),
                            [&](S2Shape *shape) {
                              best = std::min(best, s->feature_of[shape->id()]);
                              return true;
                            });
    out[i] = best;
  }
}

void s2_regions_free(S2Regions *s) { delete s; }
#else
struct S2Regions {};
S2Regions *s2_regions_build(const RegionLayer &) { return nullptr; }
void s2_regions_locate(S2Regions *, const std::vector<Pt> &, std::vector<uint32_t> &) {}
void s2_regions_free(S2Regions *) {}
#endif

} // namespace qkb

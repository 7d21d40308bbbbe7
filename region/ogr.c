/*
 * The GDAL/OGR reader: every layer's Polygon and MultiPolygon features (and the polygons
 * of GeometryCollections) of any vector format GDAL opens, attribute fields as properties. As the
 * GeoJSON reader, a feature of another geometry type stays as an empty feature (counted as
 * skipped), so that feature indices follow the dataset's order. Validation (ring length, closure,
 * coordinates) is the builder's. Without GDAL the call says what to install.
 *
 * GDAL is loaded by the first read (dlopen), not linked: linked, it made every program
 * using quadkit load GDAL and the seventy-odd libraries it needs when it started (the CLI
 * took four times as long to print its help), for a reader few runs use. The library
 * loaded is the one quadkit was built against (its soname, QK_GDAL_SONAME), or the file the
 * environment variable QK_GDAL_LIBRARY names.
 */
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#include "region/region_internal.h"

#ifdef QK_HAVE_GDAL
#include <cpl_error.h>
#include <dlfcn.h>
#include <gdal.h>
#include <ogr_api.h>
#include <pthread.h>
#include <stdlib.h>

/* The GDAL functions the reader calls, through pointers of the headers' own types. */
/* clang-format off */
#define GDAL_FUNCTIONS(X) \
  X(GDALAllRegister) X(GDALOpenEx) X(GDALClose) X(GDALDatasetGetLayerCount) \
  X(GDALDatasetGetLayer) X(OGR_L_ResetReading) X(OGR_L_GetNextFeature) X(OGR_F_Destroy) \
  X(OGR_F_GetGeometryRef) X(OGR_F_GetFieldCount) X(OGR_F_GetFieldDefnRef) \
  X(OGR_F_IsFieldSetAndNotNull) X(OGR_F_GetFieldAsString) X(OGR_Fld_GetNameRef) \
  X(OGR_G_GetGeometryType) X(OGR_GT_Flatten) X(OGR_G_GetGeometryCount) X(OGR_G_GetGeometryRef) \
  X(OGR_G_GetPointCount) X(OGR_G_GetX) X(OGR_G_GetY) X(CPLQuietErrorHandler) \
  X(CPLPushErrorHandler) X(CPLPopErrorHandler) X(CPLErrorReset) X(CPLGetLastErrorType) \
  X(CPLGetLastErrorMsg) X(OGR_G_HasCurveGeometry) X(OGR_G_GetLinearGeometry) \
  X(OGR_G_DestroyGeometry)
/* clang-format on */

static struct {
#define GDAL_POINTER(f) __typeof__(&f) f;
  GDAL_FUNCTIONS(GDAL_POINTER)
#undef GDAL_POINTER
} gd;
static bool gd_loaded;
static char gd_why[320]; /* why GDAL could not be loaded */
static pthread_once_t gd_once = PTHREAD_ONCE_INIT;

static void gd_load(void) {
  const char *file = getenv("QK_GDAL_LIBRARY");
  if (!file || !*file) file = QK_GDAL_SONAME;
  void *h = dlopen(file, RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    const char *e = dlerror();
    snprintf(gd_why, sizeof gd_why, "%.250s", e ? e : file);
    return;
  }
  void *sym;
  /* dlsym's object pointer copied into a function pointer (POSIX makes them the same size) */
#define GDAL_LOAD(f)                                                                               \
  if (!(sym = dlsym(h, #f))) {                                                                     \
    snprintf(gd_why, sizeof gd_why, "%.200s has no %s", file, #f);                                 \
    dlclose(h);                                                                                    \
    return;                                                                                        \
  }                                                                                                \
  memcpy(&gd.f, &sym, sizeof sym);
  GDAL_FUNCTIONS(GDAL_LOAD)
#undef GDAL_LOAD
  gd.GDALAllRegister();
  gd_loaded = true; /* GDAL stays loaded: its drivers are registered once */
}

typedef struct ob {
  const qk_allocator_t *a;
  qk__rings_t rg;
  bool curved; /* the feature read last has a true arc (the read fails, naming it) */
} ob_t;

static qk_status_t add_ring(ob_t *b, OGRGeometryH ring, int k) {
  int n = gd.OGR_G_GetPointCount(ring);
  qk_status_t st = qk__rings_reserve(b->a, &b->rg, (size_t)n);
  if (st) return st;
  for (int j = 0; j < n; j++) {
    b->rg.xy[2 * (b->rg.nv + (size_t)j)] = gd.OGR_G_GetX(ring, j);
    b->rg.xy[2 * (b->rg.nv + (size_t)j) + 1] = gd.OGR_G_GetY(ring, j);
  }
  qk__rings_close(&b->rg, (size_t)n, (size_t)k);
  return QK_OK;
}

static qk_status_t add_polygon(ob_t *b, OGRGeometryH poly) {
  int n = gd.OGR_G_GetGeometryCount(poly);
  for (int k = 0; k < n; k++) {
    qk_status_t st = add_ring(b, gd.OGR_G_GetGeometryRef(poly, k), k);
    if (st) return st;
  }
  return QK_OK;
}

/* The polygons of a geometry: a Polygon or a Triangle, the members of a MultiPolygon, a
 * GeometryCollection (nested ones too, as the GeoJSON reader takes them; they were counted
 * as skipped), a MultiSurface, a PolyhedralSurface or a TIN, and a CurvePolygon whose rings
 * are straight (LineStrings, or CompoundCurves of them), which GDAL converts to a Polygon
 * exactly. Every one of these is an area bounded by straight edges: GML and NAS layers
 * hold MultiSurfaces, and until the twenty-second session they were all dropped without a
 * word (their features empty, every point in them answered -1). A true arc has no exact
 * set of edges, and approximating it would make answers depend on a tolerance the caller
 * never chose: it sets b->curved and fails the read. Other types (points, lines, curves
 * that bound nothing) add nothing. */
static qk_status_t add_geometry(ob_t *b, OGRGeometryH g) {
  OGRwkbGeometryType t = g ? gd.OGR_GT_Flatten(gd.OGR_G_GetGeometryType(g)) : wkbUnknown;
  if (t == wkbPolygon || t == wkbTriangle) return add_polygon(b, g);
  if (t == wkbCurvePolygon) {
    if (gd.OGR_G_HasCurveGeometry(g, TRUE)) {
      b->curved = true;
      return QK_ERR_PARSE;
    }
    OGRGeometryH lin = gd.OGR_G_GetLinearGeometry(g, 0, NULL);
    if (!lin) return QK_ERR_NOMEM;
    qk_status_t st = gd.OGR_GT_Flatten(gd.OGR_G_GetGeometryType(lin)) == wkbPolygon
                         ? add_polygon(b, lin)
                         : QK_ERR_CORRUPT;
    gd.OGR_G_DestroyGeometry(lin);
    return st;
  }
  qk_status_t st = QK_OK;
  if (t == wkbMultiPolygon || t == wkbGeometryCollection || t == wkbMultiSurface ||
      t == wkbPolyhedralSurface || t == wkbTIN)
    for (int i = 0, n = gd.OGR_G_GetGeometryCount(g); i < n && !st; i++)
      st = add_geometry(b, gd.OGR_G_GetGeometryRef(g, i));
  return st;
}

static qk_status_t add_feature(ob_t *b, OGRFeatureH feat) {
  size_t r0 = b->rg.nr;
  qk_status_t st = add_geometry(b, gd.OGR_F_GetGeometryRef(feat));
  if (st) return st;
  if (b->rg.nr == r0) b->rg.skipped++;
  for (int i = 0, n = gd.OGR_F_GetFieldCount(feat); i < n && !st; i++) {
    const char *name = gd.OGR_Fld_GetNameRef(gd.OGR_F_GetFieldDefnRef(feat, i));
    const char *v =
        gd.OGR_F_IsFieldSetAndNotNull(feat, i) ? gd.OGR_F_GetFieldAsString(feat, i) : "";
    st = qk__props_add(b->a, &b->rg.props, name, v, strlen(v));
  }
  if (!st) st = qk__props_end_feature(b->a, &b->rg.props, b->rg.nf);
  if (!st) st = qk__rings_end_feature(b->a, &b->rg);
  return st;
}

qk_status_t qk_region_read_ogr(const char *path, const qk_region_options_t *options,
                               qk_region_t **out, qk_error_t *err) {
  qk_status_t st0 = qk__read_begin(path, out, err);
  if (st0) return st0;
  pthread_once(&gd_once, gd_load);
  if (!gd_loaded)
    return qk__region_fail(err, QK_ERR_UNSUPPORTED, SIZE_MAX,
                           "GDAL could not be loaded to read %s (%s); install GDAL's library or "
                           "name it in QK_GDAL_LIBRARY",
                           path, gd_why);
  /* GDAL's reason for a failure (a missing file said no more than "cannot open") is
   * asked for with GDAL_OF_VERBOSE_ERROR and kept quiet: the library never prints. */
  gd.CPLPushErrorHandler(gd.CPLQuietErrorHandler);
  gd.CPLErrorReset();
  GDALDatasetH ds = gd.GDALOpenEx(path, GDAL_OF_VECTOR | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR,
                                  NULL, NULL, NULL);
  gd.CPLPopErrorHandler();
  if (!ds) {
    const char *why = gd.CPLGetLastErrorMsg();
    return qk__region_fail(err, QK_ERR_IO, SIZE_MAX, "GDAL cannot open %s as vector data%s%.160s",
                           path, why && *why ? ": " : "", why ? why : "");
  }
  qk_region_options_t o;
  qk_allocator_t alloc;
  qk__region_options(options, &o, &alloc);
  ob_t b;
  memset(&b, 0, sizeof b);
  b.a = &alloc;
  qk_status_t st = QK_OK;
  /* GDAL reports a damaged record (a truncated .shp: "Error in fread() ...") by an error
   * and a feature without geometry, or by ending the layer early: either would drop
   * features without a word, and the default handler prints. Errors are kept quiet and
   * any failure while reading fails the read, naming the feature. */
  bool gdal_failed = false;
  size_t bad_feature = 0;
  char why[200] = "";
  gd.CPLPushErrorHandler(gd.CPLQuietErrorHandler);
  for (int l = 0, nl = gd.GDALDatasetGetLayerCount(ds); l < nl && !st && !gdal_failed; l++) {
    OGRLayerH layer = gd.GDALDatasetGetLayer(ds, l);
    gd.OGR_L_ResetReading(layer);
    for (;;) {
      gd.CPLErrorReset();
      OGRFeatureH feat = gd.OGR_L_GetNextFeature(layer);
      if (gd.CPLGetLastErrorType() >= CE_Failure) {
        gdal_failed = true;
        bad_feature = b.rg.nf;
        snprintf(why, sizeof why, "%s", gd.CPLGetLastErrorMsg());
      }
      if (!feat) break;
      if (!gdal_failed) st = add_feature(&b, feat);
      gd.OGR_F_Destroy(feat);
      if (st || gdal_failed) break;
    }
  }
  gd.CPLPopErrorHandler();
  gd.GDALClose(ds);
  if (gdal_failed) {
    st = qk__region_fail(err, QK_ERR_IO, bad_feature, "GDAL failed reading feature %zu: %.160s",
                         bad_feature, why);
  } else if (b.curved) {
    st = qk__region_fail(err, QK_ERR_PARSE, b.rg.nf,
                         "feature %zu: a curved geometry (an arc of a CircularString) cannot be "
                         "read exactly; convert it to straight edges first (ogr2ogr -nlt "
                         "CONVERT_TO_LINEAR)",
                         b.rg.nf);
  } else if (st) {
    qk__region_fail(err, st, SIZE_MAX, "%s while reading %s", qk_strerror(st), path);
  } else {
    st = qk__rings_build(&b.rg, &o, out, err);
  }
  qk__rings_free(&alloc, &b.rg);
  return st;
}

#else

qk_status_t qk_region_read_ogr(const char *path, const qk_region_options_t *options,
                               qk_region_t **out, qk_error_t *err) {
  (void)path, (void)options;
  if (out) *out = NULL;
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  return qk__region_fail(err, QK_ERR_UNSUPPORTED, SIZE_MAX,
                         "built without GDAL: install libgdal-dev and rebuild to read this format");
}

#endif

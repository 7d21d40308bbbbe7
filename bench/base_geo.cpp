// Baseline: GeographicLib's C++ NearestNeighbor (a vantage-point tree) with geodesic
// distances on WGS84 from Geodesic::Inverse.
#include "bench.h"

#ifdef QKB_HAVE_GEOGRAPHICLIB
#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/NearestNeighbor.hpp>

namespace qkb {

namespace {
struct GeoDist {
  double operator()(const Pt &a, const Pt &b) const {
    double s12;
    GeographicLib::Geodesic::WGS84().Inverse(a.y, a.x, b.y, b.x, s12);
    return s12;
  }
};
} // namespace

struct GeoIndex {
  const std::vector<Pt> *pts;
  GeoDist dist;
  GeographicLib::NearestNeighbor<double, Pt, GeoDist> nn;
};

GeoIndex *geo_build(const std::vector<Pt> &lonlat) {
  GeoIndex *g = new GeoIndex;
  g->pts = &lonlat;
  g->nn.Initialize(lonlat, g->dist);
  return g;
}

void geo_knn(GeoIndex *g, const std::vector<Pt> &qs, int k, std::vector<double> &dist_out) {
  std::vector<int> ind;
  dist_out.assign(qs.size() * k, INFINITY);
  for (size_t i = 0; i < qs.size(); i++) {
    // Search returns the nearest one's distance (dist(pts[ind[0]], query), as computed
    // during the search): only the others are measured again, as its documentation says.
    double nearest = g->nn.Search(*g->pts, g->dist, qs[i], ind, k);
    if (!ind.empty()) dist_out[i * k] = nearest;
    for (size_t j = 1; j < ind.size() && j < (size_t)k; j++)
      dist_out[i * k + j] = g->dist((*g->pts)[ind[j]], qs[i]);
  }
}

void geo_free(GeoIndex *g) { delete g; }

} // namespace qkb
#else
namespace qkb {
struct GeoIndex {};
GeoIndex *geo_build(const std::vector<Pt> &) { return nullptr; }
void geo_knn(GeoIndex *, const std::vector<Pt> &, int, std::vector<double> &) {}
void geo_free(GeoIndex *) {}
} // namespace qkb
#endif

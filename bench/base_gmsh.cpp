// Baseline: gmsh's 2D mesher through its C API, on the same domain as the others (the
// square [0, U]^2 with the components as holes plus the components as surfaces).
#include "bench.h"

#ifdef QKB_HAVE_GMSH
// gmshc.h declares a C API but has no extern "C" guard of its own.
extern "C" {
#include <gmshc.h>
}

#include <map>

namespace qkb {

bool gmsh_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out) {
  static bool init = false;
  int ierr = 0;
  if (!init) {
    gmshInitialize(0, nullptr, 0, &ierr);
    if (ierr) return false;
    gmshOptionSetNumber("General.Terminal", 0, &ierr);
    gmshOptionSetNumber("General.Verbosity", 0, &ierr);
    init = true;
  }
  gmshClear(&ierr);
  gmshModelAdd("bench", &ierr);
  gmshOptionSetNumber("Mesh.MeshSizeMax", max_edge, &ierr);
  gmshOptionSetNumber("Mesh.MeshSizeMin", 0, &ierr);
  gmshOptionSetNumber("Mesh.Algorithm", 5, &ierr); // Delaunay
  double t0 = now_seconds();
  auto loop = [&](const Ring &r) {
    std::vector<int> pts, lines;
    for (const Pt &p : r) pts.push_back(gmshModelGeoAddPoint(p.x, p.y, 0, max_edge, -1, &ierr));
    for (size_t i = 0; i < pts.size(); i++)
      lines.push_back(gmshModelGeoAddLine(pts[i], pts[(i + 1) % pts.size()], -1, &ierr));
    return gmshModelGeoAddCurveLoop(lines.data(), lines.size(), -1, 0, &ierr);
  };
  Ring square = {{0, 0}, {U, 0}, {U, U}, {0, U}};
  std::vector<int> loops = {loop(square)};
  std::vector<int> inner;
  for (const Ring &r : rings) inner.push_back(loop(r));
  loops.insert(loops.end(), inner.begin(), inner.end());
  gmshModelGeoAddPlaneSurface(loops.data(), loops.size(), -1, &ierr);
  for (int l : inner) gmshModelGeoAddPlaneSurface(&l, 1, -1, &ierr);
  gmshModelGeoSynchronize(&ierr);
  gmshModelMeshGenerate(2, &ierr);
  out.seconds = now_seconds() - t0;
  if (ierr) return false;

  size_t *tags = nullptr, ntags = 0, *ptags = nullptr, nptags = 0;
  double *coord = nullptr, *par = nullptr;
  size_t ncoord = 0, npar = 0;
  gmshModelMeshGetNodes(&tags, &ntags, &coord, &ncoord, &par, &npar, -1, -1, 0, 0, &ierr);
  std::map<size_t, uint32_t> idx;
  std::vector<double> xy;
  for (size_t i = 0; i < ntags; i++) {
    idx[tags[i]] = (uint32_t)i;
    xy.push_back(coord[3 * i]);
    xy.push_back(coord[3 * i + 1]);
  }
  size_t *etags = nullptr, netags = 0;
  gmshModelMeshGetElementsByType(2, &etags, &netags, &ptags, &nptags, -1, 0, 1, &ierr);
  std::vector<uint32_t> tri;
  for (size_t i = 0; i < nptags; i++) tri.push_back(idx[ptags[i]]);
  gmshFree(tags);
  gmshFree(coord);
  gmshFree(par);
  gmshFree(etags);
  gmshFree(ptags);
  out.triangles = tri.size() / 3;
  out.min_angle_deg = min_angle_of(xy, tri);
  return true;
}

} // namespace qkb
#else
namespace qkb {
bool gmsh_mesh(double, const std::vector<Ring> &, double, MeshResult &) { return false; }
} // namespace qkb
#endif

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

// Count the 2D mesh gmsh just made and measure its smallest angle.
static void read_triangles(MeshResult &out) {
  int ierr = 0;
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
}

// Initialise gmsh once per process (for both entry points below), then start an empty model
// meshed by Delaunay with edges up to max_edge. False when gmsh cannot start.
static bool start_model(double max_edge) {
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
  return true;
}

bool gmsh_mesh(double U, const std::vector<Ring> &rings, double max_edge, MeshResult &out) {
  int ierr = 0;
  if (!start_model(max_edge)) return false;
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

  read_triangles(out);
  return true;
}

// Is point p inside ring r (even-odd, floating point: the rings here are far apart)?
static bool inside_ring(const Pslg &in, const std::vector<uint32_t> &r, double px, double py) {
  bool c = false;
  for (size_t i = 0, j = r.size() - 1; i < r.size(); j = i++) {
    double ax = in.xy[2 * r[i]], ay = in.xy[2 * r[i] + 1], bx = in.xy[2 * r[j]],
           by = in.xy[2 * r[j] + 1];
    if ((ay > py) != (by > py) && px < ax + (py - ay) / (by - ay) * (bx - ax)) c = !c;
  }
  return c;
}

bool gmsh_mesh_pslg(const Pslg &in, double max_edge, MeshResult &out) {
  int ierr = 0;
  if (!start_model(max_edge)) return false;
  double t0 = now_seconds();
  std::vector<int> pt(in.xy.size() / 2);
  for (size_t i = 0; i < pt.size(); i++)
    pt[i] = gmshModelGeoAddPoint(in.xy[2 * i], in.xy[2 * i + 1], 0, max_edge, -1, &ierr);
  std::vector<int> loops(in.rings.size());
  for (size_t k = 0; k < in.rings.size(); k++) {
    const auto &r = in.rings[k];
    std::vector<int> lines;
    for (size_t i = 0; i < r.size(); i++)
      lines.push_back(gmshModelGeoAddLine(pt[r[i]], pt[r[(i + 1) % r.size()]], -1, &ierr));
    loops[k] = gmshModelGeoAddCurveLoop(lines.data(), lines.size(), -1, 0, &ierr);
  }
  // Each outer ring with the holes whose first vertex it holds.
  for (size_t k = 0; k < in.rings.size(); k++) {
    if (in.ring_sign[k] < 0) continue;
    std::vector<int> surf = {loops[k]};
    for (size_t h = 0; h < in.rings.size(); h++)
      if (in.ring_sign[h] < 0 &&
          inside_ring(in, in.rings[k], in.xy[2 * in.rings[h][0]], in.xy[2 * in.rings[h][0] + 1]))
        surf.push_back(loops[h]);
    gmshModelGeoAddPlaneSurface(surf.data(), surf.size(), -1, &ierr);
  }
  gmshModelGeoSynchronize(&ierr);
  gmshModelMeshGenerate(2, &ierr);
  out.seconds = now_seconds() - t0;
  if (ierr) return false;
  read_triangles(out);
  return true;
}

} // namespace qkb
#else
namespace qkb {
bool gmsh_mesh(double, const std::vector<Ring> &, double, MeshResult &) { return false; }
bool gmsh_mesh_pslg(const Pslg &, double, MeshResult &) { return false; }
} // namespace qkb
#endif

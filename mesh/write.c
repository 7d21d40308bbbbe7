/*
 * Mesh writers: Triangle's .node/.ele, gmsh .msh 4.1 (ASCII), VTK XML .vtu and SVG.
 * Coordinates are written as "%.17g" writes them (17 significant digits: they read back
 * bit-identical); the long loops format through mesh/numfmt.h, the same characters as
 * printf's at a fraction of its cost.
 */
#include "mesh/mesh_internal.h"
#include "mesh/numfmt.h"
#include "index/textloc.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Flushed first: what stdio still buffered would otherwise fail only at the caller's
 * fclose, after QK_OK (a small mesh on a full disk). */
static qk_status_t io_status(FILE *f) { return fflush(f) != 0 || ferror(f) ? QK_ERR_IO : QK_OK; }

static qk_status_t write_node(const qk_mesh_t *m, FILE *f, unsigned first) {
  if (!m || !f || first > 1) return QK_ERR_INVALID;
  fprintf(f, "%zu 2 0 %d\n", m->nv, m->has_marks ? 1 : 0);
  qk__wbuf_t w;
  w.f = f, w.n = 0;
  qk__dcount_t num;
  qk__dcount_init(&num, first);
  for (size_t i = 0; i < m->nv; i++) {
    /* One line formatted in place: 24 + 2 * 41 + 23 + 1 bytes at most. */
    char *p = qk__wbuf_room(&w, 192), *p0 = p;
    p += qk__dcount_put(&num, p), *p++ = ' ';
    p += qk__fmt_g17(m->xy[2 * i], p), *p++ = ' ';
    p += qk__fmt_g17(m->xy[2 * i + 1], p);
    if (m->has_marks) {
      int32_t k = m->vmark[i];
      *p++ = ' ';
      if (k < 0) *p++ = '-';
      p += qk__fmt_u64(k < 0 ? 0 - (uint64_t)k : (uint64_t)k, p);
    }
    *p++ = '\n';
    w.n += (size_t)(p - p0);
  }
  qk__wbuf_flush(&w);
  return io_status(f);
}

static qk_status_t write_poly(const qk_mesh_t *m, FILE *f, unsigned first) {
  if (!m || !f || first > 1) return QK_ERR_INVALID;
  fprintf(f, "# the vertices are those of the .node file\n0 2 0 %d\n%zu 1\n", m->has_marks ? 1 : 0,
          m->noseg);
  qk__wbuf_t w;
  w.f = f, w.n = 0;
  for (size_t i = 0; i < m->noseg; i++) {
    qk__wbuf_u(&w, i + first), qk__wbuf_c(&w, ' ');
    qk__wbuf_u(&w, (uint64_t)m->oseg[i].a + first), qk__wbuf_c(&w, ' ');
    qk__wbuf_u(&w, (uint64_t)m->oseg[i].b + first), qk__wbuf_c(&w, ' ');
    qk__wbuf_i(&w, (long)m->oseg[i].mark), qk__wbuf_c(&w, '\n');
  }
  qk__wbuf_flush(&w);
  fprintf(f, "0\n");
  return io_status(f);
}

static qk_status_t write_ele(const qk_mesh_t *m, FILE *f, unsigned first) {
  if (!m || !f || first > 1) return QK_ERR_INVALID;
  /* The component id, then the regional attribute when the input has regions. */
  fprintf(f, "%zu 3 %d\n", m->nt, m->attr ? 2 : 1);
  qk__wbuf_t w;
  w.f = f, w.n = 0;
  qk__dcount_t num;
  qk__dcount_init(&num, first);
  for (size_t i = 0; i < m->nt; i++) {
    const uint32_t *t = &m->tri[3 * i];
    /* One line formatted in place: 24 + 4 * 22 + 41 + 1 bytes at most. */
    char *p = qk__wbuf_room(&w, 192), *p0 = p;
    p += qk__dcount_put(&num, p);
    for (int j = 0; j < 3; j++) *p++ = ' ', p += qk__fmt_u64((uint64_t)t[j] + first, p);
    *p++ = ' ', p += qk__fmt_u64(m->comp[i], p);
    if (m->attr) *p++ = ' ', p += qk__fmt_g17(m->attr[i], p);
    *p++ = '\n';
    w.n += (size_t)(p - p0);
  }
  qk__wbuf_flush(&w);
  return io_status(f);
}

/* Which component ids occur, and how many triangles each has. Returns the number of
 * distinct ids; `count` has room for stats.components + 1 entries. */
static int i32_cmp(const void *a, const void *b) {
  int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
  return (x > y) - (x < y);
}

/* The distinct markers of the output segments, sorted, into marks (noseg + 1 slots). */
static size_t distinct_marks(const qk_mesh_t *m, int32_t *marks) {
  for (size_t i = 0; i < m->noseg; i++) marks[i] = m->oseg[i].mark;
  qsort(marks, m->noseg, sizeof *marks, i32_cmp);
  size_t k = 0;
  for (size_t i = 0; i < m->noseg; i++)
    if (k == 0 || marks[k - 1] != marks[i]) marks[k++] = marks[i];
  return k;
}

/* A surface entity of the .msh: the triangles of one component with one regional
 * attribute (one per component when the mesh has no attributes). */
typedef struct msh_ent {
  uint32_t comp;
  double attr;
  size_t count;
} msh_ent_t;

static int ent_cmp(const void *a, const void *b) {
  const msh_ent_t *x = a, *y = b;
  if (x->comp != y->comp) return x->comp < y->comp ? -1 : 1;
  return (x->attr > y->attr) - (x->attr < y->attr);
}

static int dbl_cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The entity of triangle i: its place in ent[0, ne) (sorted, distinct). */
static size_t ent_of(const qk_mesh_t *m, const msh_ent_t *ent, size_t ne, size_t i) {
  msh_ent_t key = {m->comp[i], m->attr ? m->attr[i] : 0, 0};
  size_t lo = 0, hi = ne;
  while (hi - lo > 1) {
    size_t mid = lo + (hi - lo) / 2;
    if (ent_cmp(&ent[mid], &key) <= 0)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

/* The place of v in the sorted distinct values r[0, nr). */
static size_t dbl_at(const double *r, size_t nr, double v) {
  size_t lo = 0, hi = nr;
  while (hi - lo > 1) {
    size_t mid = lo + (hi - lo) / 2;
    if (r[mid] <= v)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

/*
 * gmsh 4.1: the triangles of each component present, and with regional attributes of
 * each (component, attribute) pair present, form a surface entity (tag k + 1 for the k-th
 * in that order) carrying the physical group of its component (tag id + 1: `outside`
 * for 0, `component_K`) and, with attributes, the group of its region (`region_A`, tags
 * after the components': one group per attribute value present). Every boundary marker
 * of the output segments is a curve entity (tag k + 1 for the k-th smallest marker)
 * carrying a physical group of line elements (`marker_M`). All nodes are listed in one
 * block on the first surface entity, which gmsh accepts for a mesh without geometry.
 */
static qk_status_t write_msh(const qk_mesh_t *m, FILE *f) {
  if (!m || !f) return QK_ERR_INVALID;
  size_t nc = m->stats.components + 1, cap = m->nt + 1;
  msh_ent_t *ent = qk__realloc(&m->alloc, NULL, 0, cap * sizeof *ent);
  double *reg = qk__realloc(&m->alloc, NULL, 0, cap * sizeof *reg);
  int32_t *marks = qk__realloc(&m->alloc, NULL, 0, (m->noseg + 1) * sizeof *marks);
  uint32_t *eid = qk__realloc(&m->alloc, NULL, 0, cap * sizeof *eid);
  uint32_t *order = qk__realloc(&m->alloc, NULL, 0, cap * sizeof *order);
  size_t *at = qk__realloc(&m->alloc, NULL, 0, (cap + 1) * sizeof *at);
  qk_status_t st = QK_OK;
  if (!ent || !reg || !marks || !eid || !order || !at) {
    st = QK_ERR_NOMEM;
    goto done;
  }
  /* The entities, sorted and distinct, with their triangle counts; the regions. */
  for (size_t i = 0; i < m->nt; i++) ent[i] = (msh_ent_t){m->comp[i], m->attr ? m->attr[i] : 0, 0};
  qsort(ent, m->nt, sizeof *ent, ent_cmp);
  size_t ne = 0, nr = 0;
  for (size_t i = 0; i < m->nt; i++)
    if (!ne || ent_cmp(&ent[ne - 1], &ent[i])) ent[ne++] = ent[i];
  /* The triangles in order of their entities, each entity's in triangle order (a
   * counting sort: eid[i] is triangle i's entity, at[k] where entity k's run begins). */
  memset(at, 0, (ne + 1) * sizeof *at);
  for (size_t i = 0; i < m->nt; i++) eid[i] = (uint32_t)ent_of(m, ent, ne, i), at[eid[i] + 1]++;
  for (size_t k = 0; k < ne; k++) ent[k].count = at[k + 1], at[k + 1] += at[k];
  for (size_t i = 0; i < m->nt; i++) order[at[eid[i]]++] = (uint32_t)i;
  if (m->attr) {
    for (size_t k = 0; k < ne; k++) reg[k] = ent[k].attr;
    qsort(reg, ne, sizeof *reg, dbl_cmp);
    for (size_t k = 0; k < ne; k++)
      if (!nr || reg[nr - 1] != reg[k]) reg[nr++] = reg[k];
  }
  size_t ncomp = 0; /* components present */
  for (size_t k = 0; k < ne; k++) ncomp += !k || ent[k].comp != ent[k - 1].comp;
  size_t nm = m->has_marks ? distinct_marks(m, marks) : 0;
  size_t nseg = m->has_marks ? m->noseg : 0;
  double ext = ldexp((double)m->size, -m->lat.f);
  double x0 = m->lat.x0 + 0.0, y0 = m->lat.y0 + 0.0, x1 = x0 + ext, y1 = y0 + ext;
  fprintf(f, "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
  fprintf(f, "$PhysicalNames\n%zu\n", nm + ncomp + nr);
  for (size_t k = 0; k < nm; k++) fprintf(f, "1 %zu \"marker_%ld\"\n", k + 1, (long)marks[k]);
  for (size_t k = 0; k < ne; k++) {
    if (k && ent[k].comp == ent[k - 1].comp) continue;
    if (ent[k].comp == 0)
      fprintf(f, "2 1 \"outside\"\n");
    else
      fprintf(f, "2 %lu \"component_%lu\"\n", (unsigned long)ent[k].comp + 1,
              (unsigned long)ent[k].comp);
  }
  char num[QK__NUMFMT_MAX + 1];
  for (size_t r = 0; r < nr; r++) {
    num[qk__fmt_g17(reg[r], num)] = '\0';
    fprintf(f, "2 %zu \"region_%s\"\n", nc + 1 + r, num);
  }
  fprintf(f, "$EndPhysicalNames\n");
  fprintf(f, "$Entities\n0 %zu %zu 0\n", nm, ne);
  for (size_t k = 0; k < nm; k++)
    fprintf(f, "%zu %.17g %.17g 0 %.17g %.17g 0 1 %zu 0\n", k + 1, x0, y0, x1, y1, k + 1);
  for (size_t k = 0; k < ne; k++) {
    fprintf(f, "%zu %.17g %.17g 0 %.17g %.17g 0 %d %lu", k + 1, x0, y0, x1, y1, m->attr ? 2 : 1,
            (unsigned long)ent[k].comp + 1);
    if (m->attr) fprintf(f, " %zu", nc + 1 + dbl_at(reg, nr, ent[k].attr));
    fprintf(f, " 0\n");
  }
  fprintf(f, "$EndEntities\n$Nodes\n%d %zu %d %zu\n", m->nv ? 1 : 0, m->nv, m->nv ? 1 : 0, m->nv);
  if (m->nv) {
    fprintf(f, "2 %d 0 %zu\n", ne ? 1 : 0, m->nv);
    qk__wbuf_t w;
    w.f = f, w.n = 0;
    for (size_t i = 0; i < m->nv; i++) qk__wbuf_u(&w, i + 1), qk__wbuf_c(&w, '\n');
    for (size_t i = 0; i < m->nv; i++) {
      qk__wbuf_g17(&w, m->xy[2 * i]), qk__wbuf_c(&w, ' ');
      qk__wbuf_g17(&w, m->xy[2 * i + 1]), qk__wbuf_s(&w, " 0\n");
    }
    qk__wbuf_flush(&w);
  }
  size_t nel = m->nt + nseg;
  fprintf(f, "$EndNodes\n$Elements\n%zu %zu %d %zu\n", ne + nm, nel, nel ? 1 : 0, nel);
  /* Element tags are numbered block by block, so they run 1..nel in block order. */
  size_t tag = 1;
  for (size_t k = 0; k < nm; k++) {
    size_t n = 0;
    for (size_t i = 0; i < m->noseg; i++) n += m->oseg[i].mark == marks[k];
    fprintf(f, "1 %zu 1 %zu\n", k + 1, n);
    for (size_t i = 0; i < m->noseg; i++)
      if (m->oseg[i].mark == marks[k])
        fprintf(f, "%zu %lu %lu\n", tag++, (unsigned long)m->oseg[i].a + 1,
                (unsigned long)m->oseg[i].b + 1);
  }
  for (size_t k = 0, j = 0; k < ne; k++) {
    fprintf(f, "2 %zu 2 %zu\n", k + 1, ent[k].count);
    qk__wbuf_t w;
    w.f = f, w.n = 0;
    for (size_t e = j + ent[k].count; j < e; j++) {
      const uint32_t *t = &m->tri[3 * (size_t)order[j]];
      qk__wbuf_u(&w, tag++);
      for (int j = 0; j < 3; j++) qk__wbuf_c(&w, ' '), qk__wbuf_u(&w, (uint64_t)t[j] + 1);
      qk__wbuf_c(&w, '\n');
    }
    qk__wbuf_flush(&w);
  }
  fprintf(f, "$EndElements\n");
  st = io_status(f);
done:
  qk__free(&m->alloc, ent, cap * sizeof *ent);
  qk__free(&m->alloc, reg, cap * sizeof *reg);
  qk__free(&m->alloc, marks, (m->noseg + 1) * sizeof *marks);
  qk__free(&m->alloc, eid, cap * sizeof *eid);
  qk__free(&m->alloc, order, cap * sizeof *order);
  qk__free(&m->alloc, at, (cap + 1) * sizeof *at);
  return st;
}

static qk_status_t write_vtu(const qk_mesh_t *m, FILE *f) {
  if (!m || !f) return QK_ERR_INVALID;
  fprintf(f,
          "<?xml version=\"1.0\"?>\n"
          "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
          "<UnstructuredGrid>\n<Piece NumberOfPoints=\"%zu\" NumberOfCells=\"%zu\">\n",
          m->nv, m->nt);
  fprintf(f, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
  qk__wbuf_t w;
  w.f = f, w.n = 0;
  for (size_t i = 0; i < m->nv; i++) {
    qk__wbuf_g17(&w, m->xy[2 * i]), qk__wbuf_c(&w, ' ');
    qk__wbuf_g17(&w, m->xy[2 * i + 1]), qk__wbuf_s(&w, " 0\n");
  }
  qk__wbuf_s(&w, "</DataArray>\n</Points>\n<Cells>\n"
                 "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
  for (size_t i = 0; i < m->nt; i++) {
    qk__wbuf_u(&w, m->tri[3 * i]), qk__wbuf_c(&w, ' ');
    qk__wbuf_u(&w, m->tri[3 * i + 1]), qk__wbuf_c(&w, ' ');
    qk__wbuf_u(&w, m->tri[3 * i + 2]), qk__wbuf_c(&w, '\n');
  }
  qk__wbuf_s(&w, "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
  for (size_t i = 0; i < m->nt; i++) qk__wbuf_u(&w, 3 * (i + 1)), qk__wbuf_c(&w, '\n');
  qk__wbuf_s(&w, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (size_t i = 0; i < m->nt; i++) qk__wbuf_s(&w, "5\n"); /* VTK_TRIANGLE */
  qk__wbuf_s(&w, "</DataArray>\n</Cells>\n<PointData Scalars=\"marker\">\n"
                 "<DataArray type=\"Int32\" Name=\"marker\" format=\"ascii\">\n");
  for (size_t i = 0; i < m->nv; i++) qk__wbuf_i(&w, (long)m->vmark[i]), qk__wbuf_c(&w, '\n');
  qk__wbuf_s(&w, "</DataArray>\n</PointData>\n<CellData Scalars=\"component\">\n");
  /* "region" repeats the component id under the name FEM tools look for. */
  static const char *names[2] = {"component", "region"};
  for (int k = 0; k < 2; k++) {
    qk__wbuf_s(&w, "<DataArray type=\"Int32\" Name=\""), qk__wbuf_s(&w, names[k]);
    qk__wbuf_s(&w, "\" format=\"ascii\">\n");
    for (size_t i = 0; i < m->nt; i++) qk__wbuf_u(&w, m->comp[i]), qk__wbuf_c(&w, '\n');
    qk__wbuf_s(&w, "</DataArray>\n");
  }
  if (m->attr) {
    qk__wbuf_s(&w, "<DataArray type=\"Float64\" Name=\"attribute\" format=\"ascii\">\n");
    for (size_t i = 0; i < m->nt; i++) qk__wbuf_g17(&w, m->attr[i]), qk__wbuf_c(&w, '\n');
    qk__wbuf_s(&w, "</DataArray>\n");
  }
  qk__wbuf_flush(&w);
  fprintf(f, "</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
  return io_status(f);
}

/* Lattice coordinates of an input coordinate, for drawing (the tree is on the lattice). */
static double lat_x(const qk_mesh_t *m, double x) { return ldexp(x - m->lat.x0, m->lat.f); }
static double lat_y(const qk_mesh_t *m, double y) { return ldexp(y - m->lat.y0, m->lat.f); }

typedef struct svg_ctx {
  FILE *f;
  double scale, height;
} svg_ctx_t;

static qk_visit_t draw_leaf(const qk_tree_t *t, qk_node_t v, void *ud) {
  svg_ctx_t *c = ud;
  if (!qk__node_leaf(t, v)) return QK_VISIT_CONTINUE;
  qk_square_t sq = qk__node_square(t, v);
  double s = sq.side * c->scale;
  fprintf(c->f, "<rect x=\"%.3f\" y=\"%.3f\" width=\"%.3f\" height=\"%.3f\"/>\n", sq.x * c->scale,
          c->height - sq.y * c->scale - s, s, s);
  return QK_VISIT_CONTINUE;
}

static qk_status_t write_svg(const qk_mesh_t *m, FILE *f, unsigned width) {
  if (!m || !f) return QK_ERR_INVALID;
  if (width == 0) width = 800;
  double W = width, scale = W / (double)m->size;
  svg_ctx_t c = {f, scale, W};
  /* A few pale fills, cycled by component id; the outside stays white. */
  static const char *fill[] = {"#ffffff", "#c6dbef", "#fdd0a2", "#c7e9c0",
                               "#dadaeb", "#fcbba1", "#d9d9d9"};
  qk__svg_open(f, width);
  fprintf(f, "<g stroke=\"#9e9e9e\" stroke-width=\"0.4\" stroke-linejoin=\"round\">\n");
  for (size_t i = 0; i < m->nt; i++) {
    const uint32_t *t = &m->tri[3 * i];
    uint32_t k = m->comp[i];
    fprintf(f, "<polygon fill=\"%s\" points=\"", fill[k == 0 ? 0 : 1 + (k - 1) % 6]);
    for (int j = 0; j < 3; j++)
      fprintf(f, "%s%.3f,%.3f", j ? " " : "", lat_x(m, m->xy[2 * t[j]]) * scale,
              W - lat_y(m, m->xy[2 * t[j] + 1]) * scale);
    fprintf(f, "\"/>\n");
  }
  fprintf(f, "</g>\n<g fill=\"none\" stroke=\"#2b6cb0\" stroke-width=\"1\">\n");
  qk_status_t st = QK_OK;
  if (m->tree) /* (the general mode has one only when it graded: qk_mesh_tree) */
    st = qk_tree_visit(m->tree, qk_tree_root(m->tree), draw_leaf, &c);
  if (st != QK_OK) return st;
  fprintf(f, "</g>\n<g stroke=\"#c53030\" stroke-width=\"2.5\" stroke-linecap=\"round\">\n");
  for (size_t s = 0; s < m->ncs; s++) {
    uint32_t a = m->cseg[2 * s], b = m->cseg[2 * s + 1];
    fprintf(f, "<line x1=\"%.3f\" y1=\"%.3f\" x2=\"%.3f\" y2=\"%.3f\"/>\n",
            lat_x(m, m->cxy[2 * a]) * scale, W - lat_y(m, m->cxy[2 * a + 1]) * scale,
            lat_x(m, m->cxy[2 * b]) * scale, W - lat_y(m, m->cxy[2 * b + 1]) * scale);
  }
  fprintf(f, "</g>\n</svg>\n");
  return io_status(f);
}

/* The public writers: each runs in the C locale (index/textloc.h), so that its bytes are
 * the same whatever locale the program or the calling thread set ("1.5", never "1,5"). */

qk_status_t qk_mesh_write_node(const qk_mesh_t *m, FILE *f, unsigned first) {
  QK__RETURN_IN_C_LOCALE(write_node(m, f, first));
}

qk_status_t qk_mesh_write_ele(const qk_mesh_t *m, FILE *f, unsigned first) {
  QK__RETURN_IN_C_LOCALE(write_ele(m, f, first));
}

qk_status_t qk_mesh_write_poly(const qk_mesh_t *m, FILE *f, unsigned first) {
  QK__RETURN_IN_C_LOCALE(write_poly(m, f, first));
}

qk_status_t qk_mesh_write_msh(const qk_mesh_t *m, FILE *f) {
  QK__RETURN_IN_C_LOCALE(write_msh(m, f));
}

qk_status_t qk_mesh_write_vtu(const qk_mesh_t *m, FILE *f) {
  QK__RETURN_IN_C_LOCALE(write_vtu(m, f));
}

qk_status_t qk_mesh_write_svg(const qk_mesh_t *m, FILE *f, unsigned width) {
  QK__RETURN_IN_C_LOCALE(write_svg(m, f, width));
}

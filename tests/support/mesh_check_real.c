/* The rational mesh checker; see mesh_check_real.h. */
#include "mesh_check_real.h"

#include <stdio.h>
#include <stdlib.h>

#ifndef QK_HAVE_GMP
int mcr_available(void) { return 0; }
int mcr_check(const mcr_input_t *in, const mcr_mesh_t *m, char *msg, size_t msg_size) {
  (void)in, (void)m;
  snprintf(msg, msg_size, "built without GMP: nothing checked");
  return 2;
}
#else
#include <gmp.h>

int mcr_available(void) { return 1; }

/* Scratch rationals, cleared once. */
typedef struct ctx {
  mpq_t ux, uy, wx, wy, cr, dt, t0, t1, area, box;
} ctx_t;

static void ctx_init(ctx_t *c) {
  mpq_inits(c->ux, c->uy, c->wx, c->wy, c->cr, c->dt, c->t0, c->t1, c->area, c->box, NULL);
}
static void ctx_clear(ctx_t *c) {
  mpq_clears(c->ux, c->uy, c->wx, c->wy, c->cr, c->dt, c->t0, c->t1, c->area, c->box, NULL);
}

/* (u, w) = (b - a, c - a); cr = u x w, dt = u . w, all exact. */
static void vecs(ctx_t *c, const double *a, const double *b, const double *d) {
  mpq_set_d(c->t0, a[0]), mpq_set_d(c->ux, b[0]), mpq_sub(c->ux, c->ux, c->t0);
  mpq_set_d(c->wx, d[0]), mpq_sub(c->wx, c->wx, c->t0);
  mpq_set_d(c->t0, a[1]), mpq_set_d(c->uy, b[1]), mpq_sub(c->uy, c->uy, c->t0);
  mpq_set_d(c->wy, d[1]), mpq_sub(c->wy, c->wy, c->t0);
  mpq_mul(c->cr, c->ux, c->wy), mpq_mul(c->t0, c->uy, c->wx), mpq_sub(c->cr, c->cr, c->t0);
  mpq_mul(c->dt, c->ux, c->wx), mpq_mul(c->t0, c->uy, c->wy), mpq_add(c->dt, c->dt, c->t0);
}

static int cmp_u64(const void *a, const void *b) {
  uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

static int has(const uint64_t *k, size_t n, uint64_t key) {
  size_t lo = 0, hi = n;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (k[mid] < key)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < n && k[lo] == key;
}

static int check_triangles(ctx_t *c, const mcr_mesh_t *m, char *msg, size_t n) {
  mpq_set_ui(c->area, 0, 1);
  for (size_t t = 0; t < m->nt; t++) {
    const uint32_t *tr = &m->tri[3 * t];
    for (int i = 0; i < 3; i++) {
      if (tr[i] >= m->nv) return snprintf(msg, n, "triangle %zu uses vertex %u", t, tr[i]), 1;
      vecs(c, &m->xy[2 * tr[i]], &m->xy[2 * tr[(i + 1) % 3]], &m->xy[2 * tr[(i + 2) % 3]]);
      if (mpq_sgn(c->cr) <= 0)
        return snprintf(msg, n, "triangle %zu is not counter-clockwise", t), 1;
      if (mpq_sgn(c->dt) < 0) return snprintf(msg, n, "triangle %zu has an angle above 90", t), 1;
      if (mpq_cmp(c->dt, c->cr) > 0)
        return snprintf(msg, n, "triangle %zu has an angle below 45 degrees", t), 1;
      if (i == 0) mpq_add(c->area, c->area, c->cr);
    }
  }
  return 0;
}

/* Edge pairing, and twinless edges on the box (lo, hi). keys: 3 nt, sorted on return. */
static int check_edges(const mcr_mesh_t *m, uint64_t *keys, const double lo[2], const double hi[2],
                       char *msg, size_t n) {
  size_t ne = 3 * m->nt;
  for (size_t t = 0; t < m->nt; t++)
    for (int i = 0; i < 3; i++)
      keys[3 * t + i] = (uint64_t)m->tri[3 * t + i] << 32 | m->tri[3 * t + (i + 1) % 3];
  qsort(keys, ne, sizeof *keys, cmp_u64);
  for (size_t i = 1; i < ne; i++)
    if (keys[i] == keys[i - 1]) return snprintf(msg, n, "a directed edge is used twice"), 1;
  for (size_t i = 0; i < ne; i++) {
    uint32_t a = (uint32_t)(keys[i] >> 32), b = (uint32_t)keys[i];
    if (has(keys, ne, (uint64_t)b << 32 | a)) continue;
    const double *p = &m->xy[2 * a], *q = &m->xy[2 * b];
    int on = 0;
    for (int k = 0; k < 2; k++) on |= (p[k] == q[k]) && (p[k] == lo[k] || p[k] == hi[k]);
    if (!on)
      return snprintf(msg, n, "edge (%.17g,%.17g)-(%.17g,%.17g) has no twin inside the box", p[0],
                      p[1], q[0], q[1]),
             1;
  }
  return 0;
}

/* Input segment s is the chain of mesh edges between the mesh vertices exactly on it. */
static int check_segment(ctx_t *c, const mcr_input_t *in, const mcr_mesh_t *m, const uint64_t *keys,
                         size_t s, uint32_t *on, char *msg, size_t n) {
  const double *a = &in->xy[2 * in->seg[2 * s]], *b = &in->xy[2 * in->seg[2 * s + 1]];
  size_t k = 0;
  mpq_t len2, d;
  mpq_inits(len2, d, NULL);
  vecs(c, a, b, b);
  mpq_set(len2, c->dt);
  for (size_t v = 0; v < m->nv; v++) {
    vecs(c, a, b, &m->xy[2 * v]);
    if (mpq_sgn(c->cr) != 0 || mpq_sgn(c->dt) < 0 || mpq_cmp(c->dt, len2) > 0) continue;
    on[k++] = (uint32_t)v;
  }
  /* Order by parameter (insertion sort with exact comparisons; few per segment). */
  for (size_t i = 1; i < k; i++)
    for (size_t j = i; j > 0; j--) {
      vecs(c, a, b, &m->xy[2 * on[j]]);
      mpq_set(d, c->dt);
      vecs(c, a, b, &m->xy[2 * on[j - 1]]);
      if (mpq_cmp(d, c->dt) >= 0) break;
      uint32_t t = on[j];
      on[j] = on[j - 1], on[j - 1] = t;
    }
  mpq_clears(len2, d, NULL);
  if (k < 2) return snprintf(msg, n, "segment %zu has %zu mesh vertices on it", s, k), 1;
  size_t ne = 3 * m->nt;
  for (size_t i = 1; i < k; i++) {
    uint64_t p = on[i - 1], q = on[i];
    if (!has(keys, ne, p << 32 | q) && !has(keys, ne, q << 32 | p))
      return snprintf(msg, n, "segment %zu: mesh vertices %llu and %llu on it are not joined", s,
                      (unsigned long long)p, (unsigned long long)q),
             1;
  }
  return 0;
}

int mcr_check(const mcr_input_t *in, const mcr_mesh_t *m, char *msg, size_t n) {
  if (m->nv == 0 || m->nt == 0) return snprintf(msg, n, "empty mesh"), 1;
  double lo[2] = {m->xy[0], m->xy[1]}, hi[2] = {m->xy[0], m->xy[1]};
  for (size_t i = 0; i < m->nv; i++)
    for (int k = 0; k < 2; k++) {
      if (m->xy[2 * i + k] < lo[k]) lo[k] = m->xy[2 * i + k];
      if (m->xy[2 * i + k] > hi[k]) hi[k] = m->xy[2 * i + k];
    }
  for (size_t i = 0; i < in->nv; i++) {
    int found = 0;
    for (size_t j = 0; j < m->nv && !found; j++)
      found = m->xy[2 * j] == in->xy[2 * i] && m->xy[2 * j + 1] == in->xy[2 * i + 1];
    if (!found) return snprintf(msg, n, "input vertex %zu is not a mesh vertex", i), 1;
  }
  ctx_t c;
  ctx_init(&c);
  uint64_t *keys = malloc((3 * m->nt + 1) * sizeof *keys);
  uint32_t *on = malloc((m->nv + 1) * sizeof *on);
  int r = !keys || !on;
  if (r) snprintf(msg, n, "out of memory");
  if (!r) r = check_triangles(&c, m, msg, n);
  if (!r) {
    /* Twice the box's area against the sum of the cross products (twice the areas). */
    mpq_set_d(c.ux, hi[0]), mpq_set_d(c.t0, lo[0]), mpq_sub(c.ux, c.ux, c.t0);
    mpq_set_d(c.uy, hi[1]), mpq_set_d(c.t0, lo[1]), mpq_sub(c.uy, c.uy, c.t0);
    mpq_mul(c.box, c.ux, c.uy), mpq_add(c.box, c.box, c.box);
    if (!mpq_equal(c.box, c.area)) r = 1, snprintf(msg, n, "the triangles do not tile the box");
  }
  if (!r) r = check_edges(m, keys, lo, hi, msg, n);
  for (size_t s = 0; !r && s < in->ns; s++) r = check_segment(&c, in, m, keys, s, on, msg, n);
  for (size_t k = 0; !r && k < m->no; k++) {
    uint32_t s = m->oseg_of[k];
    const double *a = &in->xy[2 * in->seg[2 * s]], *b = &in->xy[2 * in->seg[2 * s + 1]];
    for (int e = 0; e < 2 && !r; e++) {
      vecs(&c, a, b, &m->xy[2 * m->oseg[2 * k + e]]);
      if (mpq_sgn(c.cr) != 0) r = 1, snprintf(msg, n, "output segment %zu is off segment %u", k, s);
    }
  }
  free(keys);
  free(on);
  ctx_clear(&c);
  return r;
}
#endif

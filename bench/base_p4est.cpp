// Baseline: p4est's 2:1 balance (p4est_balance with face connectivity, one MPI rank) on
// the unit square refined to the same leaves as the quadkit tree.
#include "bench.h"

#ifdef QKB_HAVE_P4EST
// Only MPI's C interface: the C++ bindings would need libmpi_cxx.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <p4est.h>
#include <p4est_extended.h>

#include <cstdlib>

namespace qkb {

namespace {
struct Refine {
  SplitFn split;
  void *ud;
  int max_level;
};

int refine_cb(p4est_t *p4est, p4est_topidx_t, p4est_quadrant_t *q) {
  Refine *r = (Refine *)p4est->user_pointer;
  if (q->level >= r->max_level) return 0;
  double side = 1.0 / (double)((int64_t)1 << q->level);
  double x0 = (double)q->x / (double)P4EST_ROOT_LEN, y0 = (double)q->y / (double)P4EST_ROOT_LEN;
  return r->split(x0, y0, side, q->level, r->ud) ? 1 : 0;
}

void finish() {
  sc_finalize();
  int fin = 0;
  MPI_Finalized(&fin);
  if (!fin) MPI_Finalize();
}

void init_once() {
  static bool done = false;
  if (done) return;
  done = true;
  int flag = 0;
  MPI_Initialized(&flag);
  if (!flag) MPI_Init(nullptr, nullptr);
  sc_init(sc_MPI_COMM_WORLD, 0, 0, nullptr, SC_LP_SILENT);
  p4est_init(nullptr, SC_LP_SILENT);
  atexit(finish);
}
} // namespace

bool p4est_balance_run(SplitFn split, void *ud, int max_level, BalanceResult &out) {
  init_once();
  Refine r{split, ud, max_level < P4EST_QMAXLEVEL ? max_level : P4EST_QMAXLEVEL};
  p4est_connectivity_t *conn = p4est_connectivity_new_unitsquare();
  p4est_t *p = p4est_new(sc_MPI_COMM_WORLD, conn, 0, nullptr, &r);
  p4est_refine(p, 1, refine_cb, nullptr);
  out.leaves_before = (size_t)p->global_num_quadrants;
  double t0 = now_seconds();
  p4est_balance(p, P4EST_CONNECT_FACE, nullptr);
  out.seconds = now_seconds() - t0;
  out.leaves_after = (size_t)p->global_num_quadrants;
  p4est_destroy(p);
  p4est_connectivity_destroy(conn);
  return true;
}

} // namespace qkb
#else
namespace qkb {
bool p4est_balance_run(SplitFn, void *, int, BalanceResult &) { return false; }
} // namespace qkb
#endif

// Baselines: FLANN's exact single k-d tree (KDTreeSingleIndex) and nanoflann's
// KDTreeSingleIndexAdaptor, both over doubles, both with their default leaf size (10).
#include "bench.h"
#include "parallel.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#ifdef QKB_HAVE_FLANN
#include <flann/flann.hpp>
#endif
#ifdef QKB_HAVE_NANOFLANN
#include <nanoflann.hpp>
#endif

namespace qkb {

namespace {

// A result set for nanoflann that only accumulates: count and squared-distance sum
// inside the radius, or count and id sum inside a box (the circumscribed circle is the
// search radius, the box test is exact). nanoflann (1.4.3) offers a leaf's point only when
// its distance is below worstDist(), strictly: worstDist() is the next double above r^2, so
// that a point at exactly r is offered, and addPoint keeps d2 <= r^2, the closed disc the
// other implementations report.
struct SumResultSet {
  double r2;
  uint64_t count = 0;
  double sum = 0;
  SumResultSet(double r2_) : r2(r2_) {}
  size_t size() const { return count; }
  bool full() const { return true; }
  bool addPoint(double d2, uint32_t) {
    if (d2 <= r2) {
      count++;
      sum += d2;
    }
    return true;
  }
  double worstDist() const { return std::nextafter(r2, INFINITY); }
};

struct BoxResultSet {
  const std::vector<Pt> *pts;
  double r2, xmin, ymin, xmax, ymax;
  uint64_t count = 0, idsum = 0;
  size_t size() const { return count; }
  bool full() const { return true; }
  bool addPoint(double, uint32_t id) {
    const Pt &p = (*pts)[id];
    if (p.x >= xmin && p.x <= xmax && p.y >= ymin && p.y <= ymax) {
      count++;
      idsum += id;
    }
    return true;
  }
  double worstDist() const { return r2; }
};

// Squared radius of the circle around a box of half-side h, with a little slack so that
// the corners are never cut off by rounding; the box test itself is exact.
inline double box_r2(double h) { return 2 * h * h * (1 + 1e-12) + 1e-300; }

} // namespace

#ifdef QKB_HAVE_NANOFLANN
namespace {
struct Cloud {
  const std::vector<Pt> *pts = nullptr;
  size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(uint32_t i, size_t d) const { return d ? (*pts)[i].y : (*pts)[i].x; }
  template <class B> bool kdtree_get_bbox(B &) const { return false; }
};
using NanoTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud>,
                                                     Cloud, 2, uint32_t>;

class Nano : public PointIndex {
  Cloud cloud;
  std::unique_ptr<NanoTree> tree;

public:
  const char *name() const override { return "nanoflann"; }
  bool has_threads() const override { return true; }
  void build(const std::vector<Pt> &pts) override {
    cloud.pts = &pts;
    tree.reset(new NanoTree(2, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10)));
  }
  void knn(const std::vector<Pt> &qs, int k, bool, int threads, KnnOut &out) override {
    out.ids.assign(qs.size() * k, 0xffffffffu);
    out.d2.assign(qs.size() * k, INFINITY);
    parallel_for(qs.size(), threads, [&](size_t lo, size_t hi) {
      for (size_t i = lo; i < hi; i++) {
        double q[2] = {qs[i].x, qs[i].y};
        tree->knnSearch(q, k, &out.ids[i * k], &out.d2[i * k]);
      }
    });
  }
  void radius(const std::vector<Pt> &qs, double r, uint64_t &count, double &sum) override {
    for (const Pt &c : qs) {
      SumResultSet rs(r * r);
      double q[2] = {c.x, c.y};
      tree->findNeighbors(rs, q, nanoflann::SearchParams(32, 0, false));
      count += rs.count;
      sum += rs.sum;
    }
  }
  void range(const std::vector<Pt> &qs, double h, uint64_t &count, uint64_t &idsum) override {
    for (const Pt &c : qs) {
      BoxResultSet rs{cloud.pts, box_r2(h), c.x - h, c.y - h, c.x + h, c.y + h};
      double q[2] = {c.x, c.y};
      tree->findNeighbors(rs, q, nanoflann::SearchParams(32, 0, false));
      count += rs.count;
      idsum += rs.idsum;
    }
  }
  size_t bytes() const override {
    // The tree's pool and index array, plus the caller's coordinates it reads.
    return tree->usedMemory(*tree) + cloud.pts->size() * sizeof(Pt);
  }
};
} // namespace
std::unique_ptr<PointIndex> make_nanoflann() { return std::unique_ptr<PointIndex>(new Nano); }
#else
std::unique_ptr<PointIndex> make_nanoflann() { return nullptr; }
#endif

#ifdef QKB_HAVE_FLANN
namespace {
class Flann : public PointIndex {
  using Index = flann::Index<flann::L2_Simple<double>>;
  std::unique_ptr<Index> index;
  const std::vector<Pt> *pts = nullptr;

public:
  const char *name() const override { return "flann"; }
  bool has_batch() const override { return true; }
  bool has_threads() const override { return true; }
  void build(const std::vector<Pt> &p) override {
    pts = &p;
    flann::Matrix<double> m(const_cast<double *>(&p[0].x), p.size(), 2);
    index.reset(new Index(m, flann::KDTreeSingleIndexParams(10)));
    index->buildIndex();
  }
  void knn(const std::vector<Pt> &qs, int k, bool batch, int threads, KnnOut &out) override {
    size_t nq = qs.size();
    out.ids.assign(nq * k, 0xffffffffu);
    out.d2.assign(nq * k, INFINITY);
    std::vector<size_t> idx(nq * k);
    flann::SearchParams sp(-1, 0, true);
    if (batch) {
      // One call for all queries; FLANN parallelises it itself with OpenMP.
      sp.cores = threads;
      flann::Matrix<double> q(const_cast<double *>(&qs[0].x), nq, 2);
      flann::Matrix<size_t> mi(idx.data(), nq, k);
      flann::Matrix<double> md(out.d2.data(), nq, k);
      index->knnSearch(q, mi, md, k, sp);
    } else {
      sp.cores = 1;
      parallel_for(nq, threads, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; i++) {
          flann::Matrix<double> q(const_cast<double *>(&qs[i].x), 1, 2);
          flann::Matrix<size_t> mi(&idx[i * k], 1, k);
          flann::Matrix<double> md(&out.d2[i * k], 1, k);
          index->knnSearch(q, mi, md, k, sp);
        }
      });
    }
    for (size_t i = 0; i < nq * k; i++) out.ids[i] = (uint32_t)idx[i];
  }
  void radius(const std::vector<Pt> &qs, double r, uint64_t &count, double &sum) override {
    std::vector<std::vector<size_t>> ind;
    std::vector<std::vector<double>> dd;
    flann::SearchParams sp(-1, 0, false);
    // FLANN takes the squared radius as a float: round it up, then filter exactly.
    float fr = std::nextafter((float)(r * r), INFINITY);
    for (const Pt &c : qs) {
      flann::Matrix<double> q(const_cast<double *>(&c.x), 1, 2);
      index->radiusSearch(q, ind, dd, fr, sp);
      for (double d2 : dd[0])
        if (d2 <= r * r) {
          count++;
          sum += d2;
        }
    }
  }
  void range(const std::vector<Pt> &qs, double h, uint64_t &count, uint64_t &idsum) override {
    std::vector<std::vector<size_t>> ind;
    std::vector<std::vector<double>> dd;
    flann::SearchParams sp(-1, 0, false);
    float fr = std::nextafter((float)box_r2(h), INFINITY);
    for (const Pt &c : qs) {
      flann::Matrix<double> q(const_cast<double *>(&c.x), 1, 2);
      index->radiusSearch(q, ind, dd, fr, sp);
      for (size_t id : ind[0]) {
        const Pt &p = (*pts)[id];
        if (p.x >= c.x - h && p.x <= c.x + h && p.y >= c.y - h && p.y <= c.y + h) {
          count++;
          idsum += id;
        }
      }
    }
  }
  size_t bytes() const override {
    // usedMemory() counts the tree; FLANN also keeps its own reordered copy of the points.
    return index->usedMemory() + pts->size() * sizeof(Pt);
  }
};
} // namespace
std::unique_ptr<PointIndex> make_flann() { return std::unique_ptr<PointIndex>(new Flann); }
#else
std::unique_ptr<PointIndex> make_flann() { return nullptr; }
#endif

} // namespace qkb

// quadkit-bench --op world: moving boxes, all overlapping pairs every frame.
//
// Implementations (each fed the same boxes every frame, each answering with the pair
// count and a checksum of (a, b), a < b, that the driver compares before timing):
//   quadkit   qk_world: move every box, qk_world_update, walk the pairs with
//             qk_world_pairs_parallel on the world's threads (one: the same call on the
//             calling thread alone), each worker counting and hashing its pairs into an
//             accumulator of its own, summed after the walk.
//   grid      a uniform grid as users write one: cell = the largest box, boxes filed by
//             their lower-left corner with a counting sort every frame, 3x3 cells checked.
//   sap       sort and sweep on x with the order kept from frame to frame (insertion
//             sort exploits coherence), as in many game engines.
//   box2d     b2DynamicTree (fattened AABBs, MoveProxy), then one Query per proxy.
//   bullet    btDbvt: update(leaf, volume, velocity, margin) per box (velocity: twice the
//             box's last displacement), then collideTT(root, root).
//   bullet-bp btDbvtBroadphase: setAabb per proxy, calculateOverlappingPairs, then the
//             pair cache (pairs of fattened boxes) filtered by the exact box test.
//   embree    rtcCollide on a scene rebuilt every frame: a new scene and geometry and a full
//             BVH build each frame (base_embree.cpp's embree_collide, as --op collide's).
//   embree-refit  rtcCollide on a scene and geometry kept from frame to frame, the BVH
//             refitted to the moved boxes each frame (RTC_BUILD_QUALITY_REFIT on a dynamic
//             scene; base_embree.cpp's kept-scene EmbreeBoxes, as --op collide's "reused").
// Coordinates are multiples of 1/64 below 2^17, so floats (Box2D, Bullet, Embree) hold
// them exactly and every implementation can agree with quadkit's exact doubles.
#include "bench.h"

#include "quadkit/quadkit.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>

#ifdef QKB_HAVE_BOX2D
#include <box2d/b2_dynamic_tree.h>
#endif
#ifdef QKB_HAVE_BULLET
#include <BulletCollision/BroadphaseCollision/btDbvt.h>
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/BroadphaseCollision/btOverlappingPairCache.h>
#endif

namespace qkb {

namespace {

inline bool meet(const Box &p, const Box &q) {
  return p.xmin <= q.xmax && q.xmin <= p.xmax && p.ymin <= q.ymax && q.ymin <= p.ymax;
}

inline void add_pair(PairSum &s, uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  s.pairs++;
  s.hash += (uint64_t)a * 1000003u + b;
}

double q64(double v) { return std::round(v * 64) / 64; }

// The better of two hits: the smaller parameter, then the smaller index.
inline void keep_first(Hit &best, uint32_t j, double t) {
  if (t < best.t || (t == best.t && j < best.id)) best = Hit{j, t};
}

// ---- quadkit -------------------------------------------------------------------------

class QuadkitWorld : public WorldImpl {
  qk_world_t *w = nullptr;
  std::vector<qk_handle_t> h;
  unsigned threads;
  double upd = 0;
  struct alignas(64) Sum {
    PairSum s;
  };
  std::vector<Sum> sums;

public:
  explicit QuadkitWorld(unsigned th = 1) : threads(th), sums(th) {}
  ~QuadkitWorld() override { qk_world_free(w); }
  const char *name() const override { return "quadkit"; }
  void init(const std::vector<Box> &boxes) override {
    qk_world_free(w);
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = threads;
    // QKB_WORLD_THREAD_MIN: the worlds' thread_min (an A/B of threads on small worlds).
    if (const char *m = std::getenv("QKB_WORLD_THREAD_MIN"))
      o.thread_min = std::strtoul(m, nullptr, 10);
    qk_world_new(&o, &w);
    h.resize(boxes.size());
    for (size_t i = 0; i < boxes.size(); i++) {
      qk_shape_t s = {QK_SHAPE_BOX, boxes[i].xmin, boxes[i].ymin, boxes[i].xmax, boxes[i].ymax};
      qk_world_add(w, &s, i, &h[i]);
    }
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    for (size_t i = 0; i < boxes.size(); i++) {
      qk_shape_t s = {QK_SHAPE_BOX, boxes[i].xmin, boxes[i].ymin, boxes[i].xmax, boxes[i].ymax};
      qk_world_move(w, h[i], &s);
    }
    double t0 = now_seconds();
    qk_world_update(w);
    upd = now_seconds() - t0;
    // Worker t of the walk adds into sums[t], a cache line of its own (two workers adding
    // into one line would pass it between their cores at every pair); every worker
    // number is below the threads option.
    for (Sum &s : sums) s.s = PairSum();
    qk_world_pairs_parallel(
        w, QK_PAIRS_ALL,
        [](qk_handle_t a, qk_handle_t b, unsigned worker, void *ud) {
          add_pair(((Sum *)ud)[worker].s, QK_HANDLE_SLOT(a), QK_HANDLE_SLOT(b));
          return 0;
        },
        sums.data());
    for (const Sum &s : sums) out.pairs += s.s.pairs, out.hash += s.s.hash;
  }
  size_t bytes() const override { return qk_world_bytes(w); }
  size_t pair_bytes() const override { return qk_world_pair_bytes(w); }
  double update_seconds() const override { return upd; }

  bool first_hits(const std::vector<Box> &, const std::vector<Seg> &segs, bool batch,
                  std::vector<Hit> &out) override {
    out.resize(segs.size());
    if (!batch) {
      for (size_t i = 0; i < segs.size(); i++) {
        qk_world_hit_t x;
        qk_world_raycast(w, {segs[i].px, segs[i].py}, {segs[i].qx, segs[i].qy}, &x);
        out[i] = hit_of(x);
      }
      return true;
    }
    // Kept from call to call, as a caller casting every frame keeps them.
    from.resize(segs.size()), to.resize(segs.size()), hits.resize(segs.size());
    for (size_t i = 0; i < segs.size(); i++)
      from[i] = {segs[i].px, segs[i].py}, to[i] = {segs[i].qx, segs[i].qy};
    qk_world_raycast_batch(w, from.data(), to.data(), segs.size(), hits.data());
    for (size_t i = 0; i < segs.size(); i++) out[i] = hit_of(hits[i]);
    return true;
  }
  bool overlaps(const std::vector<Box> &, const std::vector<Box> &qs, PairSum &out) override {
    if (found.empty()) found.resize(64);
    for (size_t i = 0; i < qs.size(); i++) {
      qk_shape_t s = {QK_SHAPE_BOX, qs[i].xmin, qs[i].ymin, qs[i].xmax, qs[i].ymax};
      size_t m = 0;
      qk_world_query(w, &s, found.data(), found.size(), &m);
      if (m > found.size()) {
        found.resize(2 * m);
        qk_world_query(w, &s, found.data(), found.size(), &m);
      }
      for (size_t k = 0; k < m; k++) {
        out.pairs++;
        out.hash += (uint64_t)i * 1000003u + QK_HANDLE_SLOT(found[k]);
      }
    }
    return true;
  }
  bool nearest(const std::vector<Pt> &ps, bool batch, std::vector<Hit> &out) override {
    out.resize(ps.size());
    if (!batch) {
      for (size_t i = 0; i < ps.size(); i++) {
        qk_world_hit_t x;
        size_t m = 0;
        qk_world_knn(w, {ps[i].x, ps[i].y}, 1, &x, &m);
        out[i] = m ? hit_of(x) : Hit{kNoHit, INFINITY};
      }
      return true;
    }
    from.resize(ps.size()), hits.resize(ps.size()), counts.resize(ps.size());
    for (size_t i = 0; i < ps.size(); i++) from[i] = {ps[i].x, ps[i].y};
    qk_world_knn_batch(w, from.data(), ps.size(), 1, hits.data(), counts.data());
    for (size_t i = 0; i < ps.size(); i++)
      out[i] = counts[i] ? hit_of(hits[i]) : Hit{kNoHit, INFINITY};
    return true;
  }

private:
  std::vector<qk_point_t> from, to;
  std::vector<qk_world_hit_t> hits;
  std::vector<size_t> counts;
  std::vector<qk_handle_t> found;
  static Hit hit_of(const qk_world_hit_t &x) {
    return x.h == QK_HANDLE_NONE ? Hit{kNoHit, INFINITY} : Hit{QK_HANDLE_SLOT(x.h), x.t};
  }
};

// ---- uniform grid ----------------------------------------------------------------------

class Grid : public WorldImpl {
  double cell = 1, x0 = 0, y0 = 0;
  uint32_t nx = 1, ny = 1;
  std::vector<uint32_t> start, items, cx, cy;

public:
  const char *name() const override { return "grid"; }
  void init(const std::vector<Box> &boxes) override {
    double big = 0, xmin = INFINITY, ymin = INFINITY, xmax = -INFINITY, ymax = -INFINITY;
    for (const Box &b : boxes) {
      big = std::max({big, b.xmax - b.xmin, b.ymax - b.ymin});
      xmin = std::min(xmin, b.xmin), ymin = std::min(ymin, b.ymin);
      xmax = std::max(xmax, b.xmax), ymax = std::max(ymax, b.ymax);
    }
    // The world's extent, with room for the motion; at most 4 cells per box.
    double w = std::max(xmax - xmin, ymax - ymin) * 1.5 + 1;
    x0 = xmin - w / 6, y0 = ymin - w / 6;
    cell = std::max(big, w / std::sqrt(4.0 * (double)boxes.size() + 1));
    nx = ny = (uint32_t)std::ceil(w / cell) + 1;
    start.assign((size_t)nx * ny + 1, 0);
    items.resize(boxes.size());
    cx.resize(boxes.size());
    cy.resize(boxes.size());
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    std::fill(start.begin(), start.end(), 0);
    for (size_t i = 0; i < boxes.size(); i++) {
      double fx = std::floor((boxes[i].xmin - x0) / cell),
             fy = std::floor((boxes[i].ymin - y0) / cell);
      cx[i] = (uint32_t)std::min(std::max(fx, 0.0), (double)nx - 1);
      cy[i] = (uint32_t)std::min(std::max(fy, 0.0), (double)ny - 1);
      start[(size_t)cy[i] * nx + cx[i] + 1]++;
    }
    for (size_t c = 1; c < start.size(); c++) start[c] += start[c - 1];
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < boxes.size(); i++)
      items[fill[(size_t)cy[i] * nx + cx[i]]++] = (uint32_t)i;
    // Boxes are no larger than a cell, so overlapping ones are filed in adjacent cells
    // (clamping at the border keeps that true: clamped boxes share the border cells).
    for (size_t i = 0; i < boxes.size(); i++) {
      uint32_t x1 = cx[i] + 1 < nx ? cx[i] + 1 : nx - 1, y1 = cy[i] + 1 < ny ? cy[i] + 1 : ny - 1;
      for (uint32_t y = cy[i] ? cy[i] - 1 : 0; y <= y1; y++)
        for (uint32_t x = cx[i] ? cx[i] - 1 : 0; x <= x1; x++) {
          size_t c = (size_t)y * nx + x;
          for (uint32_t k = start[c]; k < start[c + 1]; k++) {
            uint32_t j = items[k];
            if (j > i && meet(boxes[i], boxes[j])) add_pair(out, (uint32_t)i, j);
          }
        }
    }
  }
  size_t bytes() const override {
    return (start.size() + items.size() + cx.size() + cy.size()) * sizeof(uint32_t);
  }
};

// ---- sort and sweep ----------------------------------------------------------------------

class Sap : public WorldImpl {
  std::vector<uint32_t> order;

public:
  const char *name() const override { return "sap"; }
  void init(const std::vector<Box> &boxes) override {
    order.resize(boxes.size());
    for (size_t i = 0; i < boxes.size(); i++) order[i] = (uint32_t)i;
    std::sort(order.begin(), order.end(),
              [&](uint32_t a, uint32_t b) { return boxes[a].xmin < boxes[b].xmin; });
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    // Insertion sort: nearly sorted already after a frame of small moves.
    for (size_t i = 1; i < order.size(); i++) {
      uint32_t v = order[i];
      double key = boxes[v].xmin;
      size_t j = i;
      while (j > 0 && boxes[order[j - 1]].xmin > key) {
        order[j] = order[j - 1];
        j--;
      }
      order[j] = v;
    }
    for (size_t i = 0; i < order.size(); i++) {
      const Box &a = boxes[order[i]];
      for (size_t j = i + 1; j < order.size() && boxes[order[j]].xmin <= a.xmax; j++) {
        const Box &b = boxes[order[j]];
        if (a.ymin <= b.ymax && b.ymin <= a.ymax) add_pair(out, order[i], order[j]);
      }
    }
  }
  size_t bytes() const override { return order.size() * sizeof(uint32_t); }
};

// ---- Box2D ---------------------------------------------------------------------------------

#ifdef QKB_HAVE_BOX2D
class Box2dTree : public WorldImpl {
  b2DynamicTree *tree = nullptr;
  std::vector<int32> proxy;
  std::vector<Box> last;

  struct Query {
    const b2DynamicTree *tree;
    const std::vector<Box> *boxes;
    uint32_t self;
    PairSum *out;
    bool QueryCallback(int32 id) {
      uint32_t j = (uint32_t)(uintptr_t)tree->GetUserData(id);
      if (j > self && meet((*boxes)[self], (*boxes)[j])) add_pair(*out, self, j);
      return true;
    }
  };
  static b2AABB aabb(const Box &b) {
    b2AABB a;
    a.lowerBound.Set((float)b.xmin, (float)b.ymin);
    a.upperBound.Set((float)b.xmax, (float)b.ymax);
    return a;
  }

public:
  ~Box2dTree() override { delete tree; }
  const char *name() const override { return "box2d"; }
  void init(const std::vector<Box> &boxes) override {
    delete tree;
    tree = new b2DynamicTree;
    proxy.resize(boxes.size());
    for (size_t i = 0; i < boxes.size(); i++)
      proxy[i] = tree->CreateProxy(aabb(boxes[i]), (void *)(uintptr_t)i);
    last = boxes;
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    for (size_t i = 0; i < boxes.size(); i++) {
      b2Vec2 d((float)(boxes[i].xmin - last[i].xmin), (float)(boxes[i].ymin - last[i].ymin));
      tree->MoveProxy(proxy[i], aabb(boxes[i]), d);
    }
    last = boxes;
    Query q{tree, &boxes, 0, &out};
    for (size_t i = 0; i < boxes.size(); i++) {
      q.self = (uint32_t)i;
      tree->Query(&q, aabb(boxes[i]));
    }
  }
  // The tree's nodes in use (2n - 1 for n proxies) times the node size: the least the
  // tree can hold (its pool doubles, so it may hold up to twice that).
  size_t bytes() const override {
    return proxy.empty() ? 0 : sizeof(b2TreeNode) * (2 * proxy.size() - 1);
  }

  // b2DynamicTree::RayCast with the callback returning the best hit's parameter (rounded
  // up to a float), which clips the rest of the walk, as Box2D's world ray casts do.
  struct Cast {
    const b2DynamicTree *tree;
    const std::vector<Box> *boxes;
    Seg s;
    Hit best;
    float RayCastCallback(const b2RayCastInput &, int32 id) {
      uint32_t j = (uint32_t)(uintptr_t)tree->GetUserData(id);
      const Box &b = (*boxes)[j];
      if (seg_meets_box(s, b)) keep_first(best, j, seg_box_param(s, b));
      if (best.id == kNoHit) return -1; // go on unclipped
      float f = std::nextafter((float)best.t, 2.0f);
      return f > 1 ? 1 : f;
    }
  };
  bool first_hits(const std::vector<Box> &boxes, const std::vector<Seg> &segs, bool batch,
                  std::vector<Hit> &out) override {
    if (batch) return false;
    out.resize(segs.size());
    Cast c{tree, &boxes, {}, {}};
    for (size_t i = 0; i < segs.size(); i++) {
      c.s = segs[i];
      c.best = Hit{kNoHit, INFINITY};
      b2RayCastInput in;
      in.p1.Set((float)c.s.px, (float)c.s.py);
      in.p2.Set((float)c.s.qx, (float)c.s.qy);
      in.maxFraction = 1;
      tree->RayCast(&c, in);
      out[i] = c.best;
    }
    return true;
  }
  struct Over {
    const b2DynamicTree *tree;
    const std::vector<Box> *boxes;
    Box q;
    uint64_t i;
    PairSum *out;
    bool QueryCallback(int32 id) {
      uint32_t j = (uint32_t)(uintptr_t)tree->GetUserData(id);
      if (meet(q, (*boxes)[j])) out->pairs++, out->hash += i * 1000003u + j;
      return true;
    }
  };
  bool overlaps(const std::vector<Box> &boxes, const std::vector<Box> &qs, PairSum &out) override {
    Over o{tree, &boxes, {}, 0, &out};
    for (size_t i = 0; i < qs.size(); i++) {
      o.q = qs[i], o.i = i;
      tree->Query(&o, aabb(qs[i]));
    }
    return true;
  }
};
#endif

// ---- Bullet --------------------------------------------------------------------------------

#ifdef QKB_HAVE_BULLET
class BulletDbvt : public WorldImpl {
  btDbvt *tree = nullptr;
  std::vector<btDbvtNode *> leaf;
  std::vector<Box> last; // (the boxes of the frame before: each move's displacement)
  // The margin of update() and the multiple of each box's displacement since the last frame
  // that it adds in the direction of motion: 0.05 (Bullet's own broadphase margin) and 2,
  // the best single setting over the three scenes at 10^4 (docs/benchmarks.md, forty-third
  // session: until then update(leaf, volume, 0.1), with no motion, which re-inserted
  // nearly every leaf every frame and ran up to 2.3x slower). QKB_BULLET_MARGIN,
  // QKB_BULLET_PREDICT (0: update(leaf, volume, margin)) and QKB_BULLET_OPT (passes of
  // optimizeIncremental() a frame, after the updates) set them otherwise.
  double margin = env_double("QKB_BULLET_MARGIN", 0.05),
         predict = env_double("QKB_BULLET_PREDICT", 2);
  int opt_passes = (int)env_double("QKB_BULLET_OPT", 0);
  static double env_double(const char *name, double def) {
    const char *v = std::getenv(name);
    return v ? std::atof(v) : def;
  }

  struct Pairs : btDbvt::ICollide {
    const std::vector<Box> *boxes;
    PairSum *out;
    void Process(const btDbvtNode *a, const btDbvtNode *b) override {
      uint32_t i = (uint32_t)(uintptr_t)a->data, j = (uint32_t)(uintptr_t)b->data;
      if (i != j && meet((*boxes)[i], (*boxes)[j])) add_pair(*out, i, j);
    }
  };
  static btDbvtVolume vol(const Box &b) {
    return btDbvtVolume::FromMM(btVector3((btScalar)b.xmin, (btScalar)b.ymin, 0),
                                btVector3((btScalar)b.xmax, (btScalar)b.ymax, 0));
  }

public:
  ~BulletDbvt() override { delete tree; }
  const char *name() const override { return "bullet"; }
  void init(const std::vector<Box> &boxes) override {
    delete tree;
    tree = new btDbvt;
    leaf.resize(boxes.size());
    for (size_t i = 0; i < boxes.size(); i++)
      leaf[i] = tree->insert(vol(boxes[i]), (void *)(uintptr_t)i);
    last = boxes;
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    // (re-inserted only when it leaves its fat volume)
    for (size_t i = 0; i < boxes.size(); i++) {
      btDbvtVolume v = vol(boxes[i]);
      if (predict > 0) {
        const btVector3 d((btScalar)((boxes[i].xmin - last[i].xmin) * predict),
                          (btScalar)((boxes[i].ymin - last[i].ymin) * predict), 0);
        tree->update(leaf[i], v, d, (btScalar)margin);
      } else {
        tree->update(leaf[i], v, (btScalar)margin);
      }
    }
    if (predict > 0) last = boxes;
    if (opt_passes > 0) tree->optimizeIncremental(opt_passes);
    Pairs p;
    p.boxes = &boxes;
    p.out = &out;
    tree->collideTT(tree->m_root, tree->m_root, p);
  }
  size_t bytes() const override {
    return leaf.empty() ? 0 : sizeof(btDbvtNode) * (2 * leaf.size() - 1);
  }

  // btDbvt::rayTest visits every leaf whose volume the whole segment crosses (it has no
  // clipping by the best hit so far; btDbvtBroadphase::rayTest neither).
  struct Cast : btDbvt::ICollide {
    const std::vector<Box> *boxes;
    Seg s;
    Hit best;
    void Process(const btDbvtNode *n) override {
      uint32_t j = (uint32_t)(uintptr_t)n->data;
      const Box &b = (*boxes)[j];
      if (seg_meets_box(s, b)) keep_first(best, j, seg_box_param(s, b));
    }
  };
  bool first_hits(const std::vector<Box> &boxes, const std::vector<Seg> &segs, bool batch,
                  std::vector<Hit> &out) override {
    if (batch) return false;
    out.resize(segs.size());
    Cast c;
    c.boxes = &boxes;
    for (size_t i = 0; i < segs.size(); i++) {
      c.s = segs[i];
      c.best = Hit{kNoHit, INFINITY};
      btDbvt::rayTest(tree->m_root, btVector3((btScalar)c.s.px, (btScalar)c.s.py, 0),
                      btVector3((btScalar)c.s.qx, (btScalar)c.s.qy, 0), c);
      out[i] = c.best;
    }
    return true;
  }
  struct Over : btDbvt::ICollide {
    const std::vector<Box> *boxes;
    Box q;
    uint64_t i;
    PairSum *out;
    void Process(const btDbvtNode *n) override {
      uint32_t j = (uint32_t)(uintptr_t)n->data;
      if (meet(q, (*boxes)[j])) out->pairs++, out->hash += i * 1000003u + j;
    }
  };
  bool overlaps(const std::vector<Box> &boxes, const std::vector<Box> &qs, PairSum &out) override {
    Over o;
    o.boxes = &boxes, o.out = &out;
    for (size_t i = 0; i < qs.size(); i++) {
      o.q = qs[i], o.i = i;
      tree->collideTV(tree->m_root, vol(qs[i]), o);
    }
    return true;
  }
};
#endif

#ifdef QKB_HAVE_BULLET
class BulletBroadphase : public WorldImpl {
  btDbvtBroadphase *bp = nullptr;
  std::vector<btBroadphaseProxy *> proxy;

public:
  ~BulletBroadphase() override { delete bp; }
  const char *name() const override { return "bullet-bp"; }
  void init(const std::vector<Box> &boxes) override {
    delete bp;
    bp = new btDbvtBroadphase;
    proxy.resize(boxes.size());
    for (size_t i = 0; i < boxes.size(); i++) {
      const Box &b = boxes[i];
      proxy[i] = bp->createProxy(btVector3((btScalar)b.xmin, (btScalar)b.ymin, 0),
                                 btVector3((btScalar)b.xmax, (btScalar)b.ymax, 0),
                                 BOX_SHAPE_PROXYTYPE, (void *)(uintptr_t)i, 1, -1, nullptr);
    }
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    for (size_t i = 0; i < boxes.size(); i++) {
      const Box &b = boxes[i];
      bp->setAabb(proxy[i], btVector3((btScalar)b.xmin, (btScalar)b.ymin, 0),
                  btVector3((btScalar)b.xmax, (btScalar)b.ymax, 0), nullptr);
    }
    bp->calculateOverlappingPairs(nullptr);
    btOverlappingPairCache *pc = bp->getOverlappingPairCache();
    int np = pc->getNumOverlappingPairs();
    const btBroadphasePair *pairs = pc->getOverlappingPairArrayPtr();
    for (int k = 0; k < np; k++) {
      uint32_t i = (uint32_t)(uintptr_t)pairs[k].m_pProxy0->m_clientObject;
      uint32_t j = (uint32_t)(uintptr_t)pairs[k].m_pProxy1->m_clientObject;
      if (meet(boxes[i], boxes[j])) add_pair(out, i, j);
    }
  }
  size_t bytes() const override { return 0; }
};
#endif

// ---- Embree ----------------------------------------------------------------------------------

// The scene rebuilt every frame, as the target states it. Its name stays "embree"
// (the smoke test, tests/cli/bench.sh, and bench/summarize.py look it up so); its rows'
// note and the table's legend say "rebuilt every frame".
class EmbreeRebuild : public WorldImpl {
public:
  const char *name() const override { return "embree"; }
  void init(const std::vector<Box> &) override {}
  void frame(const std::vector<Box> &boxes, PairSum &out) override { embree_collide(boxes, out); }
  size_t bytes() const override { return 0; }
};

class EmbreeRefit : public WorldImpl {
  EmbreeBoxes *s = nullptr;

public:
  ~EmbreeRefit() override { embree_boxes_free(s); }
  const char *name() const override { return "embree-refit"; }
  // The scene and geometry are made here; the first frame builds the BVH, every later one
  // refits it (the geometry reads the frame's boxes through their vector).
  void init(const std::vector<Box> &boxes) override {
    embree_boxes_free(s);
    s = embree_boxes_new(boxes.size(), true);
  }
  void frame(const std::vector<Box> &boxes, PairSum &out) override {
    embree_boxes_collide(s, boxes, out);
  }
  size_t bytes() const override { return 0; }
};

} // namespace

// ---- exact answers for the baselines' candidates ------------------------------------------------

// The scenes' coordinates and the query segments' endpoints are multiples of 1/64 below
// 2^18 in magnitude: differences take 25 bits, products 50, the difference of two
// products 51, so every orientation below is exact in double.
bool seg_meets_box(const Seg &s, const Box &b) {
  if (std::max(s.px, s.qx) < b.xmin || std::min(s.px, s.qx) > b.xmax ||
      std::max(s.py, s.qy) < b.ymin || std::min(s.py, s.qy) > b.ymax)
    return false;
  // The boxes overlap; the segment then meets the box unless all four corners lie
  // strictly on one side of its line (the separating axes of a segment and a box).
  double dx = s.qx - s.px, dy = s.qy - s.py;
  int above = 0, below = 0;
  for (double x : {b.xmin, b.xmax})
    for (double y : {b.ymin, b.ymax}) {
      double o = dx * (y - s.py) - dy * (x - s.px);
      above += o > 0, below += o < 0;
    }
  return above < 4 && below < 4;
}

// The parameter of the segment's first contact with a box it meets, computed as the
// world's first hit documents it (long double slabs, clamped to [0, 1]), so the answers
// compare bit for bit; ties are broken by index.
double seg_box_param(const Seg &s, const Box &b) {
  if (b.xmin <= s.px && s.px <= b.xmax && b.ymin <= s.py && s.py <= b.ymax) return 0;
  long double v[2] = {(long double)s.qx - s.px, (long double)s.qy - s.py};
  if (v[0] * v[0] + v[1] * v[1] == 0) return 0;
  long double mn[2] = {b.xmin, b.ymin}, mx[2] = {b.xmax, b.ymax}, org[2] = {s.px, s.py};
  long double lo = 0;
  for (int k = 0; k < 2; k++) {
    if (v[k] == 0) continue;
    long double t1 = (mn[k] - org[k]) / v[k], t2 = (mx[k] - org[k]) / v[k];
    lo = std::max(lo, std::min(t1, t2));
  }
  return (double)std::min(lo, (long double)1);
}

// ---- scenes ------------------------------------------------------------------------------------

WorldScene make_world_scene(const std::string &kind, size_t n, uint64_t seed) {
  WorldScene s;
  uint64_t st = seed * 0x9E3779B97F4A7C15ull + 1;
  auto rnd = [&]() {
    uint64_t z = (st += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) * 0x1p-53;
  };
  s.boxes.resize(n);
  s.vel.resize(n);
  if (kind == "huge") {
    s.side = 131072 - 64; // sparse: groups of unit boxes over 2^17 x 2^17
  } else {
    // ~3 overlaps per box for sides 0.5-2: density 3 / 6.25.
    s.side = std::min(131000.0, std::sqrt((double)n / 0.48));
  }
  size_t nclusters = 8;
  std::vector<double> cxs(nclusters), cys(nclusters);
  for (size_t c = 0; c < nclusters; c++) cxs[c] = rnd() * s.side, cys[c] = rnd() * s.side;
  double gx = 0, gy = 0;
  for (size_t i = 0; i < n; i++) {
    double w, h, x, y;
    if (kind == "clustered") {
      // sizes over three decades (0.03 .. 30), a few large among many small
      w = q64(std::max(1.0 / 64, 0.03 * std::pow(1000.0, rnd() * rnd())));
      h = q64(std::max(1.0 / 64, w * (0.5 + rnd())));
      size_t c = (size_t)(rnd() * nclusters) % nclusters;
      double spread = s.side * 0.03;
      x = cxs[c] + (rnd() + rnd() + rnd() - 1.5) * spread;
      y = cys[c] + (rnd() + rnd() + rnd() - 1.5) * spread;
    } else if (kind == "huge") {
      // small groups of four unit-size boxes scattered over the whole world
      w = q64(0.5 + 1.5 * rnd());
      h = q64(0.5 + 1.5 * rnd());
      if (i % 4 == 0) gx = rnd() * s.side, gy = rnd() * s.side;
      x = gx + 3 * rnd(), y = gy + 3 * rnd();
    } else {
      w = q64(0.5 + 1.5 * rnd());
      h = q64(0.5 + 1.5 * rnd());
      x = rnd() * s.side, y = rnd() * s.side;
    }
    x = q64(std::min(std::max(x, 0.0), s.side - w));
    y = q64(std::min(std::max(y, 0.0), s.side - h));
    s.boxes[i] = Box{x, y, x + w, y + h};
    double a = rnd() * 6.283185307179586, sp = kind == "clustered" ? 0.25 : 0.5;
    s.vel[i] = Pt{q64(sp * std::cos(a)), q64(sp * std::sin(a))};
  }
  return s;
}

void world_step(WorldScene &s) {
  for (size_t i = 0; i < s.boxes.size(); i++) {
    Box &b = s.boxes[i];
    Pt &v = s.vel[i];
    if ((b.xmin + v.x < 0) || (b.xmax + v.x > s.side)) v.x = -v.x;
    if ((b.ymin + v.y < 0) || (b.ymax + v.y > s.side)) v.y = -v.y;
    b.xmin += v.x, b.xmax += v.x, b.ymin += v.y, b.ymax += v.y;
  }
}

std::unique_ptr<WorldImpl> make_world_quadkit(unsigned threads) {
  return std::unique_ptr<WorldImpl>(new QuadkitWorld(threads));
}

std::vector<std::unique_ptr<WorldImpl>> make_world_impls() {
  std::vector<std::unique_ptr<WorldImpl>> v;
  v.emplace_back(new QuadkitWorld);
  v.emplace_back(new Grid);
  v.emplace_back(new Sap);
#ifdef QKB_HAVE_BOX2D
  if (have("box2d")) v.emplace_back(new Box2dTree);
#endif
#ifdef QKB_HAVE_BULLET
  if (have("bullet")) v.emplace_back(new BulletDbvt);
  if (have("bullet") && !skipped("bullet-bp")) v.emplace_back(new BulletBroadphase);
#endif
  if (have("embree")) v.emplace_back(new EmbreeRebuild);
  if (have("embree") && !skipped("embree-refit")) v.emplace_back(new EmbreeRefit);
  // (QKB_SKIP names them: box2d, bullet (both of Bullet's), bullet-bp, embree (both of
  // Embree's), embree-refit; the grid and sort and sweep always run)
  // QKB_WORLD_ONLY=NAME (for profiling, e.g. under callgrind): that implementation alone.
  if (const char *only = std::getenv("QKB_WORLD_ONLY")) {
    std::vector<std::unique_ptr<WorldImpl>> one;
    for (auto &p : v)
      if (std::strcmp(p->name(), only) == 0) one.push_back(std::move(p));
    return one;
  }
  return v;
}

} // namespace qkb

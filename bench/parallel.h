// A minimal parallel for: split [0, n) into `threads` contiguous chunks.
#ifndef QUADKIT_BENCH_PARALLEL_H
#define QUADKIT_BENCH_PARALLEL_H

#include <cstddef>
#include <thread>
#include <vector>

namespace qkb {

template <class F> void parallel_for(size_t n, int threads, F fn) {
  if (threads <= 1 || n < 2) {
    fn((size_t)0, n);
    return;
  }
  std::vector<std::thread> pool;
  size_t step = (n + threads - 1) / threads;
  for (int t = 0; t < threads; t++) {
    size_t lo = t * step, hi = lo + step < n ? lo + step : n;
    if (lo >= hi) break;
    pool.emplace_back(fn, lo, hi);
  }
  for (auto &th : pool) th.join();
}

} // namespace qkb

#endif

// Splits rows [0, n) over the machine's cores. Each call of fn(begin, end) gets a disjoint
// block; results must not depend on the split (seed per row, not per thread).
#pragma once

#include <algorithm>
#include <thread>
#include <vector>

namespace insitu::sim {

template <typename Fn>
void ParallelRows(int n, Fn fn) {
  const int threads = std::clamp(static_cast<int>(std::thread::hardware_concurrency()), 1, 8);
  if (threads == 1 || n < 64) {
    fn(0, n);
    return;
  }
  std::vector<std::thread> pool;
  const int block = (n + threads - 1) / threads;
  for (int t = 0; t < threads; ++t) {
    const int b = t * block, e = std::min(n, b + block);
    if (b < e) pool.emplace_back([=] { fn(b, e); });
  }
  for (std::thread& th : pool) th.join();
}

}  // namespace insitu::sim

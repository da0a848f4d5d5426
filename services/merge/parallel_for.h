// The merge's per-batch parallelism: f(i) for every i in [0, n) on `threads` threads (the
// calling one among them), each taking the next index in turn. Why threads per call and not a
// pool kept alive: the stages call it once per batch of a few chunks, tiles or objects, whose
// work is far larger than starting a thread.
#pragma once

#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace carvemap {

// Returns once every f(i) has returned. f must be safe to call concurrently for different i;
// which thread ran which i is not defined, so callers keep results per index.
template <typename F>
void ParallelFor(size_t n, int threads, const F& f) {
  std::atomic<size_t> next{0};
  const auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < n;) f(i);
  };
  std::vector<std::jthread> pool;
  for (int t = 1; t < threads && size_t(t) < n; ++t) pool.emplace_back(work);
  work();
}

}  // namespace carvemap

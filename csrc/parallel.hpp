// Splitting a kernel's points over XLA's intra-op thread pool (the pool XLA:CPU's own loops use),
// as XLA splits a large elementwise loop over the cores.
//
// The points [0, count) are cut into chunks that the calling thread and up to num_threads() - 1 pool
// tasks claim from one atomic counter.  The caller never waits for a task to start: it processes
// every chunk nobody has claimed, then waits only for the chunks other threads are inside.  A task
// that starts late (its pool busy, or the kernel itself running on a pool thread) finds no chunk
// left and returns without touching the kernel's buffers, which the shared state does not own; so
// the scheme cannot deadlock, and a pool of one thread, or none, runs everything on the caller.
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>

#include "xla/ffi/api/ffi.h"

namespace frbjax {

namespace detail {

struct Chunks {
  std::size_t count = 0;
  std::size_t size = 1;
  std::atomic<std::size_t> next{0};
  std::atomic<int> inside{0};
  std::mutex mutex;
  std::condition_variable done;
  std::function<void(std::size_t, std::size_t)> body;

  // Claim and run chunks until none is left.
  void work() {
    for (;;) {
      inside.fetch_add(1);
      std::size_t begin = next.fetch_add(size);
      if (begin >= count) {
        leave();
        return;
      }
      body(begin, std::min(count, begin + size));
      leave();
    }
  }

  void leave() {
    if (inside.fetch_sub(1) == 1) {
      std::lock_guard<std::mutex> lock(mutex);
      done.notify_all();
    }
  }
};

}  // namespace detail

// body(begin, end) over [0, count) in chunks of at least `grain` points (a chunk should cost tens of
// microseconds: the pool's scheduling costs a few).
template <class Body>
void parallel_for(xla::ffi::ThreadPool& pool, std::size_t count, std::size_t grain, Body body) {
  std::int64_t threads = count > grain ? pool.num_threads() : 0;
  if (threads <= 1) {
    body(std::size_t(0), count);
    return;
  }
  // About four chunks per thread, for balance when points cost unequal work (early exits).
  std::size_t size = std::max(grain, (count + 4 * threads - 1) / (4 * threads));
  std::size_t chunks = (count + size - 1) / size;
  auto shared = std::make_shared<detail::Chunks>();
  shared->count = count;
  shared->size = size;
  shared->body = std::ref(body);
  std::size_t helpers = std::min<std::size_t>(static_cast<std::size_t>(threads) - 1, chunks - 1);
  for (std::size_t k = 0; k < helpers; ++k) pool.Schedule([shared] { shared->work(); });
  shared->work();
  std::unique_lock<std::mutex> lock(shared->mutex);
  shared->done.wait(lock, [&] { return shared->inside.load() == 0; });
}

}  // namespace frbjax

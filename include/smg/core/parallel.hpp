// smg/core/parallel.hpp — deterministic parallel loops on std::thread.
//
// Determinism contract (docs/design.md "Conventions"): work over [0, n) is cut into chunks whose
// boundaries depend only on n and the grain — never on the thread count — and reductions
// combine per-chunk partial results in chunk order on the calling thread. Hence the same input
// gives bit-identical output for 1, 2 or 7 threads. Threads only decide who runs a chunk.
//
// Thread count: ParallelOptions::threads if > 0, else the process default set by
// set_num_threads (0 = std::thread::hardware_concurrency()). A parallel loop started from
// inside another runs serially on its caller's thread (no oversubscription).
//
// Threads: a process-wide pool of helper threads is started on first use and grows to the
// largest count requested, so a loop costs a wake-up instead of thread creation (trainers call
// smg thousands of times per second). The calling thread always takes part. If the pool is
// busy with another caller's loop, the loop starts its own threads for that call.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "smg/core/types.hpp"

namespace smg {

// A caller's executor (its thread pool): run(context, count, threads, job, job_context) must
// call job(job_context, c) exactly once for every c in [0, count) — on any threads, in any
// order, concurrently or not — and return when all calls have returned. `threads` is the
// thread count smg would use (a hint). smg's jobs never throw (exceptions are caught inside and
// rethrown on the calling thread after run returns) and never call the executor recursively
// (nested smg loops run serially). Examples: at::parallel_for(0, count, 1, ...) in a PyTorch
// extension, an OpenMP loop (openmp_executor() below), a TBB parallel_for.
// Chunk boundaries are fixed by smg before the executor sees them, so results are bit-identical
// for any executor and thread count.
struct Executor {
  void (*run)(void* context, Index count, int threads, void (*job)(void*, Index),
              void* job_context) = nullptr;
  void* context = nullptr;
  explicit operator bool() const { return run != nullptr; }
};

struct ParallelOptions {
  int threads = 0;  // 0: the process default (set_num_threads)
  Index grain = 0;  // items per chunk; 0: automatic, a function of n only
};

namespace detail {
inline std::atomic<int>& default_threads_storage() {
  static std::atomic<int> n{0};
  return n;
}
inline Executor& default_executor_storage() {
  static Executor e;
  return e;
}
struct ScopedExecutorState {
  bool set = false;
  Executor executor;
};
inline ScopedExecutorState& scoped_executor_storage() {
  thread_local ScopedExecutorState state;
  return state;
}
inline bool& in_parallel_region() {
  thread_local bool flag = false;
  return flag;
}
struct ParallelRegionGuard {
  bool previous;
  ParallelRegionGuard() : previous(in_parallel_region()) { in_parallel_region() = true; }
  ~ParallelRegionGuard() { in_parallel_region() = previous; }
  ParallelRegionGuard(const ParallelRegionGuard&) = delete;
  ParallelRegionGuard& operator=(const ParallelRegionGuard&) = delete;
};

// Persistent helper threads. run() hands `work` to up to `helpers` pool threads and runs it on
// the caller too; it returns when every participant has returned. `work` must not throw and
// must tolerate any number of participants (parallel_for_chunks' work pulls chunks from an
// atomic counter, so a helper that joins late — or never — only changes who runs a chunk).
class ThreadPool {
 public:
  static ThreadPool& instance() {
    static ThreadPool pool;
    return pool;
  }
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;
  ~ThreadPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    work_cv_.notify_all();
    for (auto& t : threads_) t.join();
  }

  // False (nothing run) when another loop is using the pool.
  bool try_run(int helpers, const std::function<void()>& work) {
    std::unique_lock<std::mutex> busy(run_mutex_, std::try_to_lock);
    if (!busy.owns_lock()) return false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (static_cast<int>(threads_.size()) < helpers) {
        try {
          threads_.emplace_back([this] { loop(); });
        } catch (...) {
          break;  // fewer helpers: the caller runs the remaining chunks
        }
      }
      job_ = &work;
      wanted_ = helpers;
      ++generation_;
    }
    work_cv_.notify_all();
    work();
    std::unique_lock<std::mutex> lock(mutex_);
    wanted_ = 0;  // helpers that have not started by now are not needed any more
    done_cv_.wait(lock, [this] { return active_ == 0; });
    job_ = nullptr;
    return true;
  }

 private:
  ThreadPool() = default;
  void loop() {
    std::unique_lock<std::mutex> lock(mutex_);
    std::uint64_t seen = 0;
    for (;;) {
      work_cv_.wait(lock, [&] { return stop_ || (wanted_ > 0 && generation_ != seen); });
      if (stop_) return;
      seen = generation_;
      --wanted_;
      ++active_;
      const std::function<void()>* job = job_;
      lock.unlock();
      (*job)();
      lock.lock();
      if (--active_ == 0) done_cv_.notify_all();
    }
  }

  std::mutex run_mutex_;  // one loop at a time
  std::mutex mutex_;
  std::condition_variable work_cv_, done_cv_;
  std::vector<std::thread> threads_;
  const std::function<void()>* job_ = nullptr;
  int wanted_ = 0, active_ = 0;
  std::uint64_t generation_ = 0;
  bool stop_ = false;
};
}  // namespace detail

// Sets the process-wide default thread count (0 = hardware concurrency).
inline void set_num_threads(int n) { detail::default_threads_storage() = std::max(0, n); }

// Sets the process-wide executor of every parallel loop (unless a ScopedExecutor on the calling
// thread says otherwise); Executor{} restores smg's own std::thread pool. Set it once, before
// loops run (it is not synchronised with loops running at the same time).
inline void set_executor(Executor executor) { detail::default_executor_storage() = executor; }

// The executor a loop started on this thread uses: the innermost ScopedExecutor's, else the
// process-wide one (empty: smg's std::thread pool).
inline Executor current_executor() {
  const detail::ScopedExecutorState& scoped = detail::scoped_executor_storage();
  return scoped.set ? scoped.executor : detail::default_executor_storage();
}

// While it lives, the loops started on this thread run on `executor` (Executor{}: on smg's own
// pool, whatever set_executor says); the previous choice comes back when it goes out of scope.
// A per-caller choice that leaves the process-wide setting alone.
class ScopedExecutor {
 public:
  explicit ScopedExecutor(Executor executor) : previous_(detail::scoped_executor_storage()) {
    detail::scoped_executor_storage() = {true, executor};
  }
  ~ScopedExecutor() { detail::scoped_executor_storage() = previous_; }
  ScopedExecutor(const ScopedExecutor&) = delete;
  ScopedExecutor& operator=(const ScopedExecutor&) = delete;

 private:
  detail::ScopedExecutorState previous_;
};

#ifdef _OPENMP
// An executor over OpenMP (compile with -fopenmp): a process whose OpenMP threads are busy or
// spinning (PyTorch's intra-op pool) then shares them with smg instead of oversubscribing the
// cores with a second pool.
inline Executor openmp_executor() {
  Executor e;
  e.run = [](void*, Index count, int threads, void (*job)(void*, Index), void* ctx) {
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
    for (Index c = 0; c < count; ++c) job(ctx, c);
  };
  return e;
}
#endif

// The thread count a loop with ParallelOptions::threads == 0 will use (>= 1).
inline int num_threads() {
  const int n = detail::default_threads_storage();
  if (n > 0) return n;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

// Items per chunk for n items. Automatic: about 256 chunks, at least 1 item each — enough
// chunks to balance load on any realistic core count, few enough that per-chunk partials are
// cheap. Depends on n and grain only.
inline Index parallel_grain(Index n, Index grain = 0) {
  if (grain > 0) return grain;
  return std::max<Index>(1, (n + 255) / 256);
}
inline Index parallel_chunk_count(Index n, Index grain = 0) {
  if (n <= 0) return 0;
  const Index g = parallel_grain(n, grain);
  return (n + g - 1) / g;
}

// Calls f(chunk, begin, end) once for each chunk of [0, n). Chunks may run concurrently and in
// any order; f must only write memory owned by its chunk. The first exception thrown by f is
// rethrown on the calling thread after all threads have joined (remaining chunks are skipped).
template <class F>
void parallel_for_chunks(Index n, F&& f, ParallelOptions options = {}) {
  if (n <= 0) return;
  const Index grain = parallel_grain(n, options.grain);
  const Index chunks = (n + grain - 1) / grain;
  int threads = options.threads > 0 ? options.threads : num_threads();
  if (detail::in_parallel_region()) threads = 1;
  threads = static_cast<int>(std::min<Index>(threads, chunks));

  auto run_chunk = [&](Index c) {
    const Index begin = c * grain;
    f(c, begin, std::min(n, begin + grain));
  };
  if (threads <= 1) {
    detail::ParallelRegionGuard guard;
    for (Index c = 0; c < chunks; ++c) run_chunk(c);
    return;
  }

  // Runs chunk c unless an earlier chunk threw; the first exception is kept for the caller.
  std::exception_ptr error;
  std::mutex error_mutex;
  std::atomic<bool> failed{false};
  auto run_guarded = [&](Index c) {
    if (failed.load()) return;
    try {
      run_chunk(c);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  const Executor ex = current_executor();
  if (ex) {
    // The caller's pool runs the chunks; the chunking above did not depend on it.
    auto job = [](void* ctx, Index c) {
      detail::ParallelRegionGuard guard;
      (*static_cast<decltype(run_guarded)*>(ctx))(c);
    };
    ex.run(ex.context, chunks, threads, job, &run_guarded);
    if (error) std::rethrow_exception(error);
    return;
  }
  std::atomic<Index> next{0};
  auto worker = [&]() {
    detail::ParallelRegionGuard guard;
    for (;;) {
      const Index c = next.fetch_add(1);
      if (c >= chunks || failed.load()) return;
      run_guarded(c);
    }
  };
  const std::function<void()> job = worker;
  if (!detail::ThreadPool::instance().try_run(threads - 1, job)) {
    // The pool serves another caller's loop: start threads for this call.
    std::vector<std::thread> pool;
    pool.reserve(static_cast<std::size_t>(threads - 1));
    for (int t = 1; t < threads; ++t) {
      try {
        pool.emplace_back(worker);
      } catch (...) {
        break;  // could not start a thread: the caller's thread does the remaining chunks
      }
    }
    worker();
    for (auto& th : pool) th.join();
  }
  if (error) std::rethrow_exception(error);
}

// Calls f(begin, end) over deterministic chunks of [0, n).
template <class F>
void parallel_for(Index n, F&& f, ParallelOptions options = {}) {
  parallel_for_chunks(
      n, [&](Index, Index begin, Index end) { f(begin, end); }, options);
}

// Deterministic reduction: partial[c] = map(begin_c, end_c) for each chunk, then
// result = combine(...combine(combine(identity, partial[0]), partial[1])..., partial[C-1])
// on the calling thread. Bit-identical for any thread count.
template <class T, class Map, class Combine>
T parallel_reduce(Index n, const T& identity, Map&& map, Combine&& combine,
                  ParallelOptions options = {}) {
  const Index chunks = parallel_chunk_count(n, options.grain);
  std::vector<T> partial(static_cast<std::size_t>(chunks), identity);
  parallel_for_chunks(
      n,
      [&](Index c, Index begin, Index end) {
        partial[static_cast<std::size_t>(c)] = map(begin, end);
      },
      options);
  T result = identity;
  for (const T& p : partial) result = combine(result, p);
  return result;
}

namespace detail {

// Hands out scratch slots to concurrently running chunks. A chunk takes a free slot, clears
// what it reads, and gives it back: which slot a chunk gets never affects its result, so the
// output stays bit-identical for any thread count while scratch memory scales with the number
// of threads, not of blocks.
// A caller's executor may run more chunks at once than there are slots: acquire() then waits
// for a slot (a chunk holding one always finishes without waiting, so this cannot deadlock).
class SlotPool {
 public:
  explicit SlotPool(Index slots) {
    for (Index s = slots; s-- > 0;) free_.push_back(s);
  }
  Index acquire() {
    std::unique_lock<std::mutex> lock(mutex_);
    available_.wait(lock, [this] { return !free_.empty(); });
    const Index s = free_.back();
    free_.pop_back();
    return s;
  }
  void release(Index s) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      free_.push_back(s);
    }
    available_.notify_one();
  }

 private:
  std::mutex mutex_;
  std::condition_variable available_;
  std::vector<Index> free_;
};

}  // namespace detail

}  // namespace smg

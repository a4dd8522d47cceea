// calib's one executor for parallel loops: on_threads runs a worker on N
// threads and in_ranges splits [0, n) into contiguous ranges over them.
// Threads are started per call and joined before it returns (calib's loops
// are few and long: a fit's rows, a search's fits); what the loops compute
// never depends on how many threads ran them.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace cdm {

// worker() on `threads` threads, this one included; returns once every one
// has returned. A thread that cannot be started (none left, or no memory for
// one) is not an error: the ones started and this one share the work, so a
// worker takes its work from a shared queue or counter and never counts on
// company. An exception out of a worker is rethrown here (the first one)
// once all have ended.
template <class Worker> void on_threads(size_t threads, Worker &&worker) {
    std::exception_ptr first;
    std::atomic<bool> thrown{false};
    auto run = [&] {
        try {
            worker();
        } catch (...) {
            if (!thrown.exchange(true)) first = std::current_exception();
        }
    };
    std::vector<std::thread> pool;
    try { // (reserved first: a vector growing past a started thread would end the process)
        pool.reserve(threads > 1 ? threads - 1 : 0);
        for (size_t t = 1; t < threads; ++t) pool.emplace_back(run);
    } catch (...) { // no thread, or no memory for one: fewer threads
    }
    run();
    for (auto &th : pool) th.join();
    if (first) std::rethrow_exception(first);
}

// body(r0, r1) for [r0, r1) in `threads` contiguous ranges (each of at least
// `min_rows` rows: fewer ranges otherwise), on as many threads, this one
// included; in one range here when threads <= 1. The ranges depend on n,
// threads and min_rows only, never on which thread runs them: for per-row
// work whose rows are independent and written by one range only, what it
// computes does not depend on the number of threads, bit for bit (a fit's
// positions, an evaluation's; problem.h, calib/evaluation/eval.cpp). False
// when a range's body is. An exception in a range is rethrown once every
// started range has ended. The caller keeps body thread-safe (no user
// callback: those need not be reentrant).
template <class Body> bool in_ranges(size_t n, size_t threads, size_t min_rows, Body &&body) {
    const size_t T = threads > 1 ? std::min(threads, n / std::max<size_t>(min_rows, 1)) : 1;
    if (T <= 1) return body(size_t(0), n);
    std::vector<char> ok(T, 1);
    std::atomic<size_t> next{0};
    on_threads(T, [&] {
        for (size_t t; (t = next++) < T;) ok[t] = body(n * t / T, n * (t + 1) / T);
    });
    return std::all_of(ok.begin(), ok.end(), [](char c) { return c != 0; });
}

} // namespace cdm

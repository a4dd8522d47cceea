// Work over [0, n) split into contiguous ranges, one thread each: for
// per-row work whose rows are independent and written by one range only, so
// that what it computes does not depend on the number of threads, bit for
// bit (a fit's positions, an evaluation's; problem.h, calib/evaluation/eval.cpp).
#pragma once

#include <algorithm>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace cdm {

// body(r0, r1) for [r0, r1) in `threads` contiguous ranges (each of at least
// `min_rows` rows: fewer ranges otherwise), on as many threads, this one
// included; in one range here when threads <= 1 or no thread can be started
// (the rest of the ranges then run here in turn). False when a range's
// body is. An exception in a range is rethrown once every range has ended.
// The caller keeps body thread-safe (no user callback: those need not be
// reentrant).
template <class Body> bool in_ranges(size_t n, size_t threads, size_t min_rows, Body &&body) {
    const size_t T = threads > 1 ? std::min(threads, n / std::max<size_t>(min_rows, 1)) : 1;
    if (T <= 1) return body(size_t(0), n);
    std::vector<char> ok(T, 1);
    std::vector<std::exception_ptr> thrown(T);
    auto run = [&](size_t t) {
        try {
            ok[t] = body(n * t / T, n * (t + 1) / T);
        } catch (...) {
            thrown[t] = std::current_exception();
        }
    };
    std::vector<std::thread> pool;
    size_t started = 1;
    try { // (reserved first: a vector growing past a started thread would end the process)
        pool.reserve(T - 1);
        for (; started < T; ++started) pool.emplace_back(run, started);
    } catch (...) { // no thread, or no memory for one: the rest here
    }
    run(0);
    for (size_t t = started; t < T; ++t) run(t);
    for (auto &th : pool) th.join();
    for (auto &e : thrown)
        if (e) std::rethrow_exception(e);
    return std::all_of(ok.begin(), ok.end(), [](char c) { return c != 0; });
}

} // namespace cdm

// The seqlock under one writer and several readers: no reader ever sees a
// mix of two writes (every word of a snapshot carries the same counter), and
// versions never go backwards.
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "device/seqlock.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
extern "C" {
#include <cmocka.h>
}

namespace {

// 26 words, about the size of the published pose + raw record.
struct Blob {
    uint64_t w[26];
};

void test_no_torn_reads(void **) {
    cdm::SeqLock<Blob> lock;
    Blob b;
    assert_false(lock.load(b)); // nothing stored yet
    std::atomic<bool> stop{false};
    std::atomic<uint64_t> torn{0}, reads{0}, backwards{0};
    std::vector<std::thread> readers;
    for (int r = 0; r < 3; ++r) {
        readers.emplace_back([&] {
            uint64_t last = 0;
            Blob s;
            while (!stop.load(std::memory_order_relaxed)) {
                if (!lock.load(s)) continue;
                for (uint64_t v : s.w)
                    if (v != s.w[0]) {
                        torn.fetch_add(1);
                        break;
                    }
                if (s.w[0] < last) backwards.fetch_add(1);
                last = s.w[0];
                reads.fetch_add(1, std::memory_order_relaxed);
            }
        });
    }
    // Driven by counts, not by a clock: the writer stores in bursts and,
    // after each, waits until some reader has completed a read, so the
    // readers make progress however the threads are scheduled (a sanitizer
    // or a loaded machine slows them, never fails the test).
    constexpr uint64_t kMinWrites = 50000, kMinReads = 2000;
    uint64_t k = 1;
    while (k <= kMinWrites || reads.load() < kMinReads) {
        for (int burst = 0; burst < 100; ++burst, ++k) {
            for (uint64_t &v : b.w) v = k;
            lock.store(b);
        }
        const uint64_t seen = reads.load();
        while (reads.load() == seen) std::this_thread::yield();
    }
    stop = true;
    for (auto &t : readers) t.join();
    print_message("%llu writes, %llu reads, %llu torn\n", (unsigned long long)k, (unsigned long long)reads.load(),
                  (unsigned long long)torn.load());
    assert_true(reads.load() >= kMinReads);
    assert_int_equal(torn.load(), 0);
    assert_int_equal(backwards.load(), 0);
    assert_true(lock.version() == k - 1);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {cmocka_unit_test(test_no_torn_reads)};
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}

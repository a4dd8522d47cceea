// No allocation after cdm_open: a second of streaming from sim: through
// cdm_get_pose, cdm_get_raw, cdm_wait_pose and cdm_wait_pose_after, with
// every allocation in the process counted, per thread.
//
// How allocations are counted: this program defines malloc, calloc,
// realloc, free and the aligned variants (the set glibc's manual lists under
// "Replacing malloc"), each counting and then forwarding to glibc's own
// __libc_* entry point. The executable comes first in symbol lookup, so these
// definitions serve every caller in the process: libcdm's code, libstdc++
// (its operator new calls malloc), libc itself, hidapi. The alternatives see
// less: -Wl,--wrap=malloc redirects only the references of the objects in
// this link (not libstdc++'s operator new, not libc's internal calls), and a
// replaced operator new alone misses malloc. dlsym(RTLD_NEXT, "malloc") would
// do, but dlsym may itself call calloc before the pointer is known;
// __libc_malloc and friends have no such bootstrap problem.
//
// Under AddressSanitizer or ThreadSanitizer the sanitizer owns malloc, and
// replacing it underneath would hand its chunks to glibc: the counting is
// compiled out there and the tests skip (the plain build runs them).
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <thread>

#include "cdm/cdm.h"

extern "C" {
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define CDM_COUNT_ALLOCS 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define CDM_COUNT_ALLOCS 0
#endif
#endif
#ifndef CDM_COUNT_ALLOCS
#define CDM_COUNT_ALLOCS 1
#endif

namespace {

// Calls of any allocating or freeing function: by this thread, and by all.
// A thread_local of a trivial type in the executable lives in static TLS:
// touching it allocates nothing.
thread_local uint64_t t_calls = 0;
std::atomic<uint64_t> g_calls{0};

} // namespace

#if CDM_COUNT_ALLOCS
namespace {
inline void count() {
    ++t_calls;
    g_calls.fetch_add(1, std::memory_order_relaxed);
}
} // namespace

extern "C" {
void *__libc_malloc(size_t);
void *__libc_calloc(size_t, size_t);
void *__libc_realloc(void *, size_t);
void __libc_free(void *);
void *__libc_memalign(size_t, size_t);

void *malloc(size_t n) {
    count();
    return __libc_malloc(n);
}
void *calloc(size_t k, size_t n) {
    count();
    return __libc_calloc(k, n);
}
void *realloc(void *p, size_t n) {
    count();
    return __libc_realloc(p, n);
}
void *reallocarray(void *p, size_t k, size_t n) {
    count();
    if (n && k > SIZE_MAX / n) {
        errno = ENOMEM;
        return nullptr;
    }
    return __libc_realloc(p, k * n);
}
void free(void *p) {
    if (p) count();
    __libc_free(p);
}
void *memalign(size_t a, size_t n) {
    count();
    return __libc_memalign(a, n);
}
void *aligned_alloc(size_t a, size_t n) {
    count();
    return __libc_memalign(a, n);
}
int posix_memalign(void **out, size_t a, size_t n) {
    count();
    if (a < sizeof(void *) || (a & (a - 1))) return EINVAL;
    void *p = __libc_memalign(a, n);
    if (!p) return ENOMEM;
    *out = p;
    return 0;
}
void *valloc(size_t n) {
    count();
    return __libc_memalign(4096, n);
}
} // extern "C"
#endif

namespace {

uint64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1000000000ull + uint64_t(ts.tv_nsec);
}

// Keeps the compiler from pairing an allocation with its free and dropping
// both (it may, for malloc/free and for new/delete).
void escape(void *p) { asm volatile("" : : "g"(p) : "memory"); }

void skip_if_not_counting() {
#if !CDM_COUNT_ALLOCS
    std::printf("skipped: this build's sanitizer owns malloc; the plain build counts\n");
    skip();
#endif
}

// The counter counts: each kind of call on this thread, and a call on
// another thread in the total but not in this thread's count.
void test_counter_counts(void **) {
    skip_if_not_counting();
    uint64_t before = t_calls;
    void *p = std::malloc(24);
    escape(p);
    assert_int_equal(t_calls - before, 1);
    p = std::realloc(p, 4096);
    escape(p);
    assert_int_equal(t_calls - before, 2);
    std::free(p);
    assert_int_equal(t_calls - before, 3);
    before = t_calls;
    int *q = new int(7);
    escape(q);
    assert_true(t_calls - before >= 1);
    delete q;
    assert_true(t_calls - before >= 2);
    before = t_calls;
    void *c = std::calloc(3, 8);
    escape(c);
    std::free(c);
    assert_int_equal(t_calls - before, 2);

    // Another thread, started before the measurement (starting one allocates
    // here): its malloc shows in the total, not in this thread's count.
    std::atomic<int> step{0};
    uint64_t theirs = 0;
    std::thread other([&] {
        while (step.load() != 1) std::this_thread::yield();
        const uint64_t b = t_calls;
        void *r = std::malloc(40);
        escape(r);
        std::free(r);
        theirs = t_calls - b;
        step.store(2);
    });
    const uint64_t mine0 = t_calls, all0 = g_calls.load();
    step.store(1);
    while (step.load() != 2) std::this_thread::yield();
    const uint64_t mine = t_calls - mine0, all = g_calls.load() - all0;
    other.join();
    assert_int_equal(theirs, 2);
    assert_int_equal(mine, 0);
    assert_true(all >= 2);
}

struct Streamed {
    uint64_t mine = 0, all = 0; // allocation calls during the second
    uint64_t calls = 0, poses = 0, bad_rc = 0;
};

// One second of a haptic loop's calls, after a warm-up that lets every lazy
// initialisation (first pose, first wait) happen.
Streamed stream_one_second(cdm_device *dev) {
    Streamed s;
    cdm_pose p{};
    p.struct_size = sizeof p;
    cdm_raw r{};
    r.struct_size = sizeof r;
    uint64_t after = 0;
    while (after < 200) {
        if (cdm_wait_pose_after(dev, after, 2000, &p) != CDM_OK) break;
        after = p.host_sequence;
        cdm_get_pose(dev, &p);
        cdm_get_raw(dev, &r);
        cdm_wait_pose(dev, 100, &p);
    }
    const uint64_t first = after;
    const uint64_t mine0 = t_calls, all0 = g_calls.load();
    const uint64_t end = now_ns() + 1000000000ull;
    while (now_ns() < end) {
        int rc = cdm_wait_pose_after(dev, after, 100, &p);
        s.bad_rc += rc != CDM_OK && rc != CDM_ERR_STALE;
        after = p.host_sequence;
        for (int k = 0; k < 10; ++k) {
            rc = cdm_get_pose(dev, &p);
            s.bad_rc += rc != CDM_OK && rc != CDM_ERR_STALE;
        }
        rc = cdm_get_raw(dev, &r);
        s.bad_rc += rc != CDM_OK && rc != CDM_ERR_STALE;
        rc = cdm_wait_pose(dev, 100, &p);
        s.bad_rc += rc != CDM_OK && rc != CDM_ERR_STALE;
        after = p.host_sequence > after ? p.host_sequence : after;
        s.calls += 13;
    }
    s.mine = t_calls - mine0;
    s.all = g_calls.load() - all0;
    s.poses = after - first;
    return s;
}

void test_streaming_second_on_sim(void **) {
    skip_if_not_counting();
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?motion=random&rate=1000", &dev), CDM_OK);
    const Streamed s = stream_one_second(dev);
    cdm_close(dev);
    // The caller's thread is the only one in the process besides the
    // reader: the difference is the reader thread's.
    std::printf("sim: %llu calls, %llu new poses; allocation calls: caller %llu, reader thread %llu\n",
                (unsigned long long)s.calls, (unsigned long long)s.poses, (unsigned long long)s.mine,
                (unsigned long long)(s.all - s.mine));
    assert_int_equal(s.bad_rc, 0);
    assert_true(s.poses > 0); // it did stream
    assert_int_equal(s.mine, 0);
    assert_int_equal(s.all - s.mine, 0);
}

// A user effect on the cable's path that reads the geometry (apply_geom,
// since 1.2), in the simulator's truth and in the calibration the reader
// thread solves the forward kinematics with: every evaluation at one
// position (the simulator's readings, each Gauss-Newton step's central
// differences) calls it with n = 1, and nothing around the call allocates.
// The callback itself allocates nothing either (the cable-sag physics).
int sag_geom(void *, const double *p, size_t n, const cdm_effect_context *c, double *v) {
    for (size_t i = 0; i < n; ++i)
        for (size_t k = 0; k < 4; ++k) {
            const double uz = c->unit[3 * (4 * i + k) + 2], L = c->chord_mm[4 * i + k];
            v[4 * i + k] += p[0] * L * L * L * (1 - uz * uz);
        }
    return 0;
}

void test_streaming_second_with_geometry_effect(void **) {
    skip_if_not_counting();
    static const char *const names[] = {"c"}, *const units[] = {"1/mm^2"};
    static const double scale[] = {1e-8}, lower[] = {0}, upper[] = {1e-6};
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.n_params = 1;
    d.name = "noalloc_sag";
    d.param_names = names;
    d.param_units = units;
    d.param_scale = scale;
    d.lower = lower;
    d.upper = upper;
    d.apply_geom = sag_geom;
    d.stage = CDM_EFFECT_STAGE_PATH;
    assert_int_equal(cdm_effect_register(&d), CDM_OK);
    static const char json[] = "{\"format\": \"cdm-calibration\", \"version\": 1, "
                               "\"device\": {\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30}, "
                               "\"effects\": [{\"name\": \"cable_gain\", \"params\": {\"g1\": 0.001, "
                               "\"g2\": 0, \"g3\": 0, \"g4\": 0}}, "
                               "{\"name\": \"noalloc_sag\", \"params\": {\"c\": 4e-8}}]}";
    cdm_calibration *cal = nullptr;
    assert_int_equal(cdm_calibration_parse(json, sizeof json - 1, &cal), CDM_OK);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?motion=random&rate=1000&effects=noalloc_sag", &dev), CDM_OK);
    assert_int_equal(cdm_set_calibration(dev, cal), CDM_OK);
    cdm_calibration_free(cal);
    const Streamed s = stream_one_second(dev);
    cdm_close(dev);
    std::printf("sim: with a path-stage geometry effect: %llu new poses; allocation calls: caller %llu, reader "
                "thread %llu\n",
                (unsigned long long)s.poses, (unsigned long long)s.mine, (unsigned long long)(s.all - s.mine));
    assert_int_equal(s.bad_rc, 0);
    assert_true(s.poses > 0);
    assert_int_equal(s.mine, 0);
    assert_int_equal(s.all - s.mine, 0);
    assert_int_equal(cdm_effect_unregister("noalloc_sag"), CDM_OK);
}

// A control thread's very first cdm_* call is cdm_get_pose (or
// cdm_get_raw): nothing on that thread allocates, including the first use
// of the thread error it sets (an initial-exec TLS pointer: a std::string
// thread_local's first use registers its destructor, and may allocate).
// Both a success and a failure (a constant text), each on a new thread.
void test_first_call_on_a_new_thread(void **) {
    skip_if_not_counting();
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?motion=random&rate=1000", &dev), CDM_OK);
    cdm_pose warm{};
    warm.struct_size = sizeof warm;
    assert_int_equal(cdm_wait_pose_after(dev, 0, 2000, &warm), CDM_OK);
    for (int fail = 0; fail < 2; ++fail) {
        uint64_t calls = ~0ull;
        int rc = 0;
        std::thread t([&] {
            cdm_pose p{};
            p.struct_size = fail ? 4 : sizeof p; // 4: refused, with a text
            cdm_raw r{};
            r.struct_size = sizeof r;
            const uint64_t b = t_calls;
            rc = cdm_get_pose(dev, &p);
            int rr = cdm_get_raw(dev, &r);
            escape(&rr);
            const char *text = cdm_thread_error();
            escape(const_cast<char *>(text));
            calls = t_calls - b;
        });
        t.join();
        assert_int_equal(rc, fail ? CDM_ERR_INVALID_ARG : CDM_OK);
        assert_int_equal(calls, 0);
    }
    cdm_close(dev);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_counter_counts),
        cmocka_unit_test(test_streaming_second_on_sim),
        cmocka_unit_test(test_streaming_second_with_geometry_effect),
        cmocka_unit_test(test_first_call_on_a_new_thread),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}

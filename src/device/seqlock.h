// A single-writer sequence lock over a trivially copyable value, built from
// std::atomic words so that the concurrent copy is not a data race (Boehm,
// "Can seqlocks get along with programming language memory models?", 2012).
//
// The writer (the reader thread) never waits. A reader never blocks and
// never takes a lock: it retries only while a write is under way, which is
// a copy of ~200 bytes. That is what makes cdm_get_pose real-time safe.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace cdm {

template <class T>
class SeqLock {
    static_assert(std::is_trivially_copyable<T>::value, "SeqLock copies bytes");
    static constexpr size_t kWords = (sizeof(T) + 7) / 8;
    static_assert(std::atomic<uint64_t>::is_always_lock_free, "words must be lock-free atomics");

public:
    SeqLock() {
        for (auto &w : words_) w.store(0, std::memory_order_relaxed);
    }

    // Writer only (one thread).
    void store(const T &v) {
        uint64_t tmp[kWords] = {};
        std::memcpy(tmp, &v, sizeof(T));
        const uint64_t s = seq_.load(std::memory_order_relaxed);
        seq_.store(s + 1, std::memory_order_relaxed); // odd: write under way
        // Release on each word instead of a standalone fence: a reader that
        // sees any new word then sees the odd count and retries. Same code on
        // x86 (plain moves), and ThreadSanitizer, which does not model
        // fences, can check it.
        for (size_t i = 0; i < kWords; ++i) words_[i].store(tmp[i], std::memory_order_release);
        seq_.store(s + 2, std::memory_order_release);
    }

    // Any thread. Returns false (out untouched) if nothing was ever stored.
    bool load(T &out) const {
        uint64_t tmp[kWords];
        for (;;) {
            const uint64_t s1 = seq_.load(std::memory_order_acquire);
            if (s1 & 1) {
                spin_pause();
                continue;
            }
            // Acquire on each word (the pair of the writer's release): the
            // second count read cannot be older than any word's writer.
            for (size_t i = 0; i < kWords; ++i) tmp[i] = words_[i].load(std::memory_order_acquire);
            if (seq_.load(std::memory_order_relaxed) == s1) {
                if (s1 == 0) return false;
                std::memcpy(&out, tmp, sizeof(T));
                return true;
            }
        }
    }

    // Number of completed stores (a version counter).
    uint64_t version() const { return seq_.load(std::memory_order_acquire) / 2; }

private:
    static void spin_pause() {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
    }
    std::atomic<uint64_t> seq_{0};
    std::atomic<uint64_t> words_[kWords];
};

} // namespace cdm

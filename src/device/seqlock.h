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
    bool load(T &out) const { return load_part<0>(out); }

    // Any thread. Like load, but copies only the member of type M at byte
    // `Offset` of T (a multiple of 8): the words around it are not read. The
    // member is still consistent with the rest of the value it was stored
    // with; a reader that needs only part of a large value copies only it.
    // The words go straight into `out` (through no buffer: 8-byte stores
    // read back by wider loads stall store forwarding, which cost more than
    // the copy): a retry overwrites a torn copy, and `out` holds one only
    // while load_part runs.
    template <size_t Offset, class M>
    bool load_part(M &out) const {
        static_assert(std::is_trivially_copyable<M>::value, "SeqLock copies bytes");
        static_assert(Offset % 8 == 0 && Offset + sizeof(M) <= sizeof(T), "a whole-word part of T");
        constexpr size_t first = Offset / 8, n = (sizeof(M) + 7) / 8;
        unsigned char *dst = reinterpret_cast<unsigned char *>(&out);
        for (;;) {
            const uint64_t s1 = seq_.load(std::memory_order_acquire);
            if (s1 == 0) return false;
            if (s1 & 1) {
                spin_pause();
                continue;
            }
            // Acquire on each word (the pair of the writer's release): the
            // second count read cannot be older than any word's writer.
            for (size_t i = 0; i < n; ++i) {
                const uint64_t w = words_[first + i].load(std::memory_order_acquire);
                std::memcpy(dst + 8 * i, &w, i + 1 < n ? 8 : sizeof(M) - 8 * i);
            }
            if (seq_.load(std::memory_order_relaxed) == s1) return true;
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

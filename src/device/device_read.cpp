// The callers' side of cdm_device: pose snapshots, waits for a new pose,
// info and statistics. What the reader thread publishes (device.cpp) is
// read here without locks on the haptic path (cdm_get_pose: a sequence-lock
// snapshot, no allocation, no blocking); only the waits take the mutex.
#include "device/device.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>
#include <thread>

using namespace cdm;

// `st`: the state flags loaded *before* the pose snapshot. The reader
// publishes its last pose before it sets END_OF_STREAM (or DISCONNECTED), so
// a flag seen first guarantees the snapshot that follows holds every pose
// published before it: an ended stream never looks empty.
int cdm_device::finish(cdm_pose &pose, bool have, uint32_t st) const {
    if (!have) {
        pose = cdm_pose{};
        pose.struct_size = sizeof(cdm_pose);
        pose.orientation[0] = 1.0; // identity: never the zero quaternion
        pose.flags = st;
        if (st & CDM_POSE_DISCONNECTED) return CDM_ERR_DISCONNECTED;
        if (st & CDM_POSE_END_OF_STREAM) return CDM_ERR_END_OF_STREAM;
        return CDM_ERR_NO_DATA;
    }
    pose.flags |= st;
    const uint64_t limit = uint64_t(stale_timeout_us_.load(std::memory_order_relaxed)) * 1000u;
    if (older_than(pose.host_time_ns, limit)) pose.flags |= CDM_POSE_STALE;
    if (st & CDM_POSE_DISCONNECTED) return CDM_ERR_DISCONNECTED;
    if (st & CDM_POSE_END_OF_STREAM) return CDM_ERR_END_OF_STREAM;
    if (pose.flags & CDM_POSE_NO_POSITION) return CDM_ERR_NO_DATA;
    if (pose.flags & CDM_POSE_STALE) return CDM_ERR_STALE;
    return CDM_OK;
}

// CLOCK_MONOTONIC every time (a TSC read and its scaling in the vDSO, about
// 20 ns, half of cdm_get_pose), not CLOCK_MONOTONIC_COARSE (the time of the
// kernel's last timekeeping tick, 5 ns): the kernel does not bound the
// coarse clock's lag behind the fine one. On a tickless VM (4 ms
// resolution) it lagged by more than its resolution in 73 % of samples, up
// to 6.9 ms, and with it a pose past a 50 ms deadline was reported fresh
// (CDM_OK, no STALE) up to 8 ms late, past a 5 ms one up to 1.9 ms late.
// test_fault_stale_never_late holds it; docs/performance.md ("The haptic
// path") has the clocks' costs.
bool cdm_device::older_than(uint64_t host_ns, uint64_t limit_ns) const {
    const uint64_t now = monotonic_ns();
    return now > host_ns && now - host_ns > limit_ns;
}

int cdm_device::get_pose(cdm_pose &out) const {
    const uint32_t st = state_flags_.load(std::memory_order_acquire);
    // The pose's words only, straight into out: the raw report beside it
    // would be 80 more bytes copied for nothing.
    const bool have = snap_.load_part<offsetof(Snapshot, pose)>(out);
    return finish(out, have, st);
}

int cdm_device::get_raw(cdm_raw &out) const {
    const uint32_t st = state_flags_.load(std::memory_order_acquire);
    Snapshot s;
    const bool have = snap_.load(s);
    cdm_pose p{};
    if (have) p = s.pose;
    const int rc = finish(p, have, st);
    if (have) {
        out = s.raw;
    } else {
        out = cdm_raw{};
        out.struct_size = sizeof(cdm_raw);
    }
    return rc;
}

// Sleeps until ready() or timeout (< 0: none); returns whether ready()
// held. The waiter count lets the reader skip the mutex when nobody waits.
bool cdm_device::wait_until(const std::function<bool()> &ready, int timeout_ms) {
    if (ready()) return true;
    waiters_.fetch_add(1);
    bool ok;
    {
        std::unique_lock<std::mutex> lock(wait_mu_);
        auto pred = [&] { return ready() || closing_.load(); };
        if (timeout_ms < 0) {
            wait_cv_.wait(lock, pred);
            ok = true;
        } else {
            ok = wait_cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), pred);
        }
    }
    waiters_.fetch_sub(1);
    return ok && ready();
}

// A wait on the reader thread itself (from a sample or event callback)
// would wait for a pose only that thread can publish: until the timeout,
// and without one until cdm_close. It returns CDM_ERR_INVALID_ARG at once,
// *out zeroed (orientation the identity).
bool cdm_device::on_reader_thread() const {
    return std::this_thread::get_id() == reader_id_.load(std::memory_order_acquire);
}

namespace {
int refused_on_reader_thread(cdm_pose &out) {
    out = cdm_pose{};
    out.orientation[0] = 1.0; // identity, as before the first report: never the zero quaternion
    return CDM_ERR_INVALID_ARG;
}
} // namespace

cdm_device::WaitScope::WaitScope(cdm_device &d) : dev(d) {
    std::lock_guard<std::mutex> lock(dev.wait_mu_);
    ++dev.waits_in_progress_;
}

// Last touch of the handle by a wait: the destructor may free it as soon as
// the lock is released.
cdm_device::WaitScope::~WaitScope() {
    std::lock_guard<std::mutex> lock(dev.wait_mu_);
    if (--dev.waits_in_progress_ == 0 && dev.closing_.load()) dev.wait_cv_.notify_all();
}

// A wait that a close (or cdm_shutdown) ended, or that began after one: no
// pose, CDM_ERR_CLOSED.
int cdm_device::closed_wait(cdm_pose &out) const {
    out = cdm_pose{};
    out.struct_size = sizeof(cdm_pose);
    out.orientation[0] = 1.0; // identity: never the zero quaternion
    return CDM_ERR_CLOSED;
}

int cdm_device::wait_pose(int timeout_ms, cdm_pose &out) {
    if (on_reader_thread()) return refused_on_reader_thread(out);
    WaitScope scope(*this);
    if (closing_.load()) return closed_wait(out);
    const uint64_t start = events_.load();
    bool woke = true;
    if (!(state_flags_.load() & CDM_POSE_END_OF_STREAM))
        woke = wait_until([&] { return events_.load() != start; }, timeout_ms);
    if (closing_.load()) return closed_wait(out);
    const int rc = get_pose(out);
    if (!woke && rc != CDM_ERR_NO_DATA && rc != CDM_ERR_DISCONNECTED) return CDM_ERR_TIMEOUT;
    return rc;
}

int cdm_device::wait_pose_after(uint64_t after, int timeout_ms, cdm_pose &out) {
    if (on_reader_thread()) return refused_on_reader_thread(out);
    WaitScope scope(*this);
    if (closing_.load()) return closed_wait(out);
    // Ready on a newer pose, or once no newer pose can ever come.
    const bool woke = wait_until(
        [&] {
            return published_.load() > after ||
                   (state_flags_.load() & CDM_POSE_END_OF_STREAM);
        },
        timeout_ms);
    if (closing_.load()) return closed_wait(out);
    const int rc = get_pose(out);
    if (rc == CDM_ERR_END_OF_STREAM) return rc;
    if (!woke || out.host_sequence <= after) return rc == CDM_ERR_DISCONNECTED ? rc : CDM_ERR_TIMEOUT;
    return rc;
}

void cdm_device::get_info(cdm_device_info &out) const {
    std::lock_guard<std::mutex> lock(info_mu_);
    out = info_;
}

void cdm_device::get_stats(cdm_stats &out) const {
    cdm_stats s{};
    s.struct_size = sizeof s;
    s.reports = n_reports_.load(std::memory_order_relaxed);
    s.malformed = n_malformed_.load(std::memory_order_acquire);
    s.dropped = n_dropped_.load(std::memory_order_relaxed);
    s.out_of_workspace = n_oow_.load(std::memory_order_relaxed);
    s.reconnects = n_reconnects_.load(std::memory_order_relaxed);
    s.sequence_jumps = n_seq_jumps_.load(std::memory_order_relaxed);
    s.out_of_order = n_out_of_order_.load(std::memory_order_relaxed);
    s.replay_truncated_bytes = truncated_bytes_;
    s.restarts = n_restarts_.load(std::memory_order_relaxed);
    out = s;
}

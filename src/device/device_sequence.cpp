// The reader thread's bookkeeping of the device's report counter
// (docs/protocol.md, "Sequence numbers"): each parsed report is the next,
// a gap (dropped), a duplicate or late one (out_of_order), a restart of the
// counter (restarts) or a jump (sequence_jumps). Reader thread only.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "device/device.h"

using namespace cdm;

// The sequence number's bound (docs/protocol.md, "Sequence numbers"): a
// device cannot send more reports than rate x elapsed time. A forward jump
// beyond twice that (plus 64 for reports queued in the kernel and USB
// batching) is a reset or a corrupted counter: counted in sequence_jumps,
// not in dropped, and the count restarts from it. One flipped bit thus costs
// two jumps (there and back), never 4e9 dropped reports. The elapsed time
// is the longer of the host's (between receipts) and the device's (between
// sample times): after a burst the host receives the reports it kept back
// to back, so its own clock says almost no time passed while the device's
// says how many it sampled meanwhile; lost reports are then counted as
// lost, not as a jump. The device's clock is used only where it is
// trustworthy (device_clock_trusted): a corrupted sample time must not
// turn a corrupted counter into billions of drops.
// The device's sample time of a report is trusted for the sequence bound
// when it moved forward since the last report and has not run ahead of the
// host's clock since the anchor (the first report, or the first after a
// reconnection or after the device's clock went back) by more than the
// kernel queue's 64 reports plus 100 ms of delivery latency, with 0.1 %
// between the two clocks' rates (a crystal is within 0.01 %).
bool cdm_device::device_clock_trusted(uint64_t device_us, uint64_t host_ns) const {
    if (after_reconnect_ || device_us <= last_device_us_ || device_us < anchor_device_us_) return false;
    const double slack_ns = 64.0 / conv_.rate_hz * 1e9 + 1e8;
    return double(device_us - anchor_device_us_) * 1e3 <= double(host_ns - anchor_host_ns_) * 1.001 + slack_ns;
}

// The furthest a counter may have moved over `reports` report periods:
// twice them (jitter, the two clocks) plus the kernel queue's 64.
static double count_bound(double reports) { return 2.0 * reports + 64.0; }

// Report periods in `ns` of host time at the nominal rate.
double cdm_device::periods(uint64_t ns) const { return double(ns) * 1e-9 * conv_.rate_hz; }

// The newest report's counter and times; a new stretch of the device's
// clock (the first report, after a reconnection, a restart or a wrap)
// anchors device_clock_trusted there.
void cdm_device::remember(uint32_t seq, uint64_t device_us, uint64_t host_ns) {
    if (!have_last_ || after_reconnect_ || device_us < last_device_us_) {
        anchor_device_us_ = device_us;
        anchor_host_ns_ = host_ns;
    }
    have_last_ = true;
    after_reconnect_ = false;
    last_seq_ = seq;
    last_device_us_ = device_us;
    last_host_ns_ = host_ns;
}

bool cdm_device::account_sequence(uint32_t seq, uint64_t device_us, uint64_t host_ns) {
    if (!have_last_) {
        remember(seq, device_us, host_ns);
        return true;
    }
    if (is_late(seq, device_us)) {
        n_out_of_order_.fetch_add(1, std::memory_order_relaxed);
        return false;
    }
    const uint32_t d = seq - last_seq_; // wraps at 2^32 by design
    const double host_reports = periods(host_ns - last_host_ns_);
    const double device_reports = device_clock_trusted(device_us, host_ns)
                                      ? double(device_us - last_device_us_) * 1e-6 * conv_.rate_hz
                                      : 0.0;
    const double elapsed_reports = std::max(host_reports, device_reports);
    if (d != 1 && restart_undone(seq, device_us, host_ns)) {
        // The counter is back where it was before the "restart": two jumps.
    } else if (d >= 1 && d < 0x80000000u && double(d - 1) <= count_bound(elapsed_reports)) {
        n_dropped_.fetch_add(d - 1, std::memory_order_relaxed);
    } else {
        account_discontinuity(seq, host_ns, elapsed_reports);
    }
    // The count went past the number before the restart: a real one.
    if (have_restart_ && seq - restart_.seq < 0x80000000u && seq - restart_.seq > kReorderWindow)
        have_restart_ = false;
    remember(seq, device_us, host_ns);
    return true;
}

// A duplicate or a late report: up to kReorderWindow numbers behind the
// newest (or around the number before a restart just counted: a report of
// the old count), and sampled no later than the newest. A late report is
// at most that many periods old (twice, for jitter): a device clock that
// went back further is a device that restarted its clock. Never right
// after a reconnection (the device may have restarted).
bool cdm_device::is_late(uint32_t seq, uint64_t device_us) const {
    if (after_reconnect_ || device_us > last_device_us_) return false;
    const double window_us = 2.0 * (kReorderWindow + 1) * 1e6 / conv_.rate_hz;
    if (double(last_device_us_ - device_us) > window_us) return false;
    if (last_seq_ - seq <= kReorderWindow) return true;
    return have_restart_ && (restart_.seq - seq <= kReorderWindow || seq - restart_.seq <= kReorderWindow);
}

// A "restart" that was a corrupted counter (a flipped bit that lowered
// it): the count comes back, sampled later, within the bound of the number
// before it. The restart and its drops are taken back, and the way there
// and back are two jumps.
bool cdm_device::restart_undone(uint32_t seq, uint64_t device_us, uint64_t host_ns) {
    if (!have_restart_ || device_us <= last_device_us_) return false;
    const uint32_t u = seq - restart_.seq;
    const double since = count_bound(periods(host_ns - restart_.host_ns));
    if (u < 1 || u >= 0x80000000u || double(u) > since) return false;
    n_restarts_.fetch_sub(1, std::memory_order_relaxed);
    n_dropped_.fetch_sub(restart_.dropped, std::memory_order_relaxed);
    n_seq_jumps_.fetch_add(2, std::memory_order_relaxed);
    have_restart_ = false;
    return true;
}

// A discontinuity is, in order:
// - the return of the newest jump: the counter is back within the bound of
//   the number before that jump (a flipped bit undone, after one or more
//   reports with the flipped counter): a jump;
// - a restart: a step back to a number the device could have counted to
//   from 0 since the last report (a firmware restart, a brown-out): the
//   numbers below it were sent and never arrived (dropped += seq);
//   remembered, so that a counter that comes back (restart_undone) or a
//   late report of the old count (is_late) is told apart;
// - a jump otherwise (a corrupted counter). After an unplug the device may
//   have restarted its counter (it lost power): what was missed while it
//   was away is estimated from the host clock instead.
void cdm_device::account_discontinuity(uint32_t seq, uint64_t host_ns, double elapsed_reports) {
    const double bound = count_bound(elapsed_reports);
    const uint32_t since_jump = seq - jump_from_seq_;
    const double jump_bound = count_bound(periods(host_ns - jump_from_host_ns_));
    const bool returned = have_jump_ && since_jump >= 1 && since_jump < 0x80000000u && double(since_jump) <= jump_bound;
    if (!returned && seq < last_seq_ && double(seq) <= bound) {
        const double missed = after_reconnect_ ? std::max(double(seq), elapsed_reports - 1.0) : double(seq);
        const uint64_t lost = uint64_t(std::llround(missed));
        n_restarts_.fetch_add(1, std::memory_order_relaxed);
        n_dropped_.fetch_add(lost, std::memory_order_relaxed);
        have_jump_ = false;
        have_restart_ = true;
        restart_ = {last_seq_, last_host_ns_, lost};
        return;
    }
    n_seq_jumps_.fetch_add(1, std::memory_order_relaxed);
    if (returned) {
        have_jump_ = false;
    } else {
        have_jump_ = true;
        jump_from_seq_ = last_seq_;
        jump_from_host_ns_ = last_host_ns_;
    }
    if (after_reconnect_ && elapsed_reports > 1.0)
        n_dropped_.fetch_add(uint64_t(std::llround(elapsed_reports - 1.0)), std::memory_order_relaxed);
}

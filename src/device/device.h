// The opaque cdm_device: a transport, the reader thread that turns its
// reports into poses, and the publication that hands them to any thread.
//
// Threading model (docs/protocol.md, "Threading"):
//  - The reader thread is the only one that reads the transport, parses,
//    converts and publishes. It never waits for a consumer (except through a
//    sample callback the user installed, which is the point of one).
//  - cdm_get_pose / cdm_get_raw read the seqlock and a few atomics: no lock,
//    no allocation, no system call but the vDSO's CLOCK_MONOTONIC.
//  - cdm_wait_pose sleeps on a condition variable that the reader thread
//    signals only when someone is waiting (an atomic waiter count).
//  - cdm_set_calibration hands a new model over a mutex shared only with the
//    reader thread, which looks at it only when an atomic flag says it
//    changed.
//  - Error text, device info and calibration I/O each have their own small
//    mutex; none is ever taken by cdm_get_pose.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "cdm/cdm.h"
#include "device/protocol.h"
#include "device/seqlock.h"
#include "device/transport.h"
#include "device/velocity.h"
#include "model/model.h"

namespace cdm {

constexpr uint32_t kDefaultStaleTimeoutUs = 50000;
// A calibration is for one frame: its a, b and m (mm) may differ from what
// the device reports by at most this much each. A frame is built to its
// drawing within a fraction of a millimetre, and the calibration's effects
// absorb that; a larger difference is another frame (a 150 mm calibration
// on a 300 mm master put poses 307 mm off, flagged COMPENSATED).
constexpr double kGeometryToleranceMm = 1.0;
// Read timeout of the reader thread: bounds how long cdm_close waits.
constexpr int kReaderPollMs = 50;
// A report whose sequence number is the last one's or behind it by at most
// this many, and whose device time is not newer, is a duplicate or arrived
// late (reordered): it is discarded
// (an older sample must not replace a newer one) and counted in
// cdm_stats.out_of_order. A larger backward step is a counter reset.
constexpr uint32_t kReorderWindow = 64;
// Retry interval while disconnected, when no hot-plug event comes sooner
// (cdm_device::wait_for_arrival).
constexpr int kReconnectIntervalMs = 250;

uint64_t monotonic_ns();

// Fills a public cdm_device_info from the device-info feature report.
void device_info_from_report(const proto::DeviceInfoReport &r, const char *transport, const std::string &uri,
                             cdm_device_info &out);

// Resolves NULL/"" ($CDM_DEVICE, else the first hid device) and opens.
// Returns CDM_OK or a cdm_error with err naming the URI and what failed.
int open_device(const char *uri, const cdm_open_options *opts, cdm_device **out, std::string &err);

} // namespace cdm

struct cdm_device {
public:
    // The callbacks and user pointer of `opts` (NULL: none).
    cdm_device(cdm::TransportPtr t, const cdm::proto::DeviceInfoReport &info, uint32_t stale_timeout_us,
               const cdm_open_options *opts);
    // Stops and joins the reader thread, after waking every cdm_wait_pose*
    // in progress (CDM_ERR_CLOSED) and waiting for those calls to leave.
    // On the reader thread itself (close_from_callback) it does not join.
    ~cdm_device();
    cdm_device(const cdm_device &) = delete;
    cdm_device &operator=(const cdm_device &) = delete;

    void start();
    // cdm_shutdown: every wait in progress, and every later one, returns
    // CDM_ERR_CLOSED; the handle stays valid (cdm_close frees it).
    void shutdown();
    // cdm_close on the reader thread (from a callback or a log sink there):
    // shuts down, and the reader thread frees the handle once the callback
    // returns, instead of joining itself.
    void close_from_callback();

    // Full-size (current version) outputs; the API layer trims to the
    // caller's struct_size.
    int get_pose(cdm_pose &out) const;
    int wait_pose(int timeout_ms, cdm_pose &out);
    int wait_pose_after(uint64_t after, int timeout_ms, cdm_pose &out);
    // True on the reader thread (in a sample or event callback).
    bool on_reader_thread() const;
    int get_raw(cdm_raw &out) const;
    void get_info(cdm_device_info &out) const;
    void get_stats(cdm_stats &out) const;
    void set_stale_timeout(uint32_t us) {
        stale_timeout_us_.store(us ? us : cdm::kDefaultStaleTimeoutUs, std::memory_order_relaxed);
    }
    void error_text(char *buf, size_t len) const;
    // The text cdm_device_error returns; also logged (cdm_set_log_fn) at
    // `level`, or not at all with level < 0.
    void set_error(const std::string &text, int level = 2);

    // NULL model: back to the nominal one built from the device info.
    void set_model(const cdm::ModelPtr &model);
    // "" when the calibration's frame (a, b, m) is the device's within
    // kGeometryToleranceMm each, else why not, with the numbers.
    std::string geometry_mismatch(const cdm::Model &model) const;

    int calibration_read(char *buf, size_t cap, size_t *len);
    int calibration_write(const char *data, size_t len);

    cdm::Transport &transport() { return *transport_; }

private:
    struct Snapshot {
        cdm_pose pose; // flags: only the per-report ones (COMPENSATED, OUT_OF_WORKSPACE)
        cdm_raw raw;
    };
    // Conversion constants from the device info, owned by the reader thread.
    struct Conversion {
        double scale[4], offset[4];
        double hall_closed, hall_open, grip_open_rad, rate_hz;
        uint32_t adc_full_scale; // 2^adc_bits - 1: a pot reading there is clipped, not a length
    };

    void run();
    bool try_reconnect();
    void wait_for_arrival();
    // host_ns: CLOCK_MONOTONIC when the transport's read returned it.
    void handle_report(const uint8_t *buf, size_t len, uint64_t host_ns);
    // A report the parser rejected: counted by kind, its reason kept in the
    // handle's error text (reader thread). Returns the reason in words.
    std::string reject_report(int reason, const uint8_t *buf, size_t len);
    // Hands a discarded report to on_rejected (if any).
    void tell_rejected(uint32_t kind, const uint8_t *buf, size_t len, uint64_t source_ns, const std::string &why);
    // false: discard (duplicate or late). host_ns: the receipt time the
    // counters are judged by (a replay's recorded one).
    bool account_sequence(uint32_t seq, uint64_t device_us, uint64_t host_ns);
    // A discontinuity of the counter (not a gap, not out of order): a
    // restart, or a jump. elapsed_reports: what the device could have sent
    // since the last report.
    void account_discontinuity(uint32_t seq, uint64_t host_ns, double elapsed_reports);
    bool is_late(uint32_t seq, uint64_t device_us) const;
    bool restart_undone(uint32_t seq, uint64_t device_us, uint64_t host_ns);
    bool device_clock_trusted(uint64_t device_us, uint64_t host_ns) const;
    double periods(uint64_t ns) const;
    void remember(uint32_t seq, uint64_t device_us, uint64_t host_ns);
    bool wait_until(const std::function<bool()> &ready, int timeout_ms);
    // Counts a wait in progress for the destructor (RAII).
    struct WaitScope {
        explicit WaitScope(cdm_device &d);
        ~WaitScope();
        cdm_device &dev;
    };
    int closed_wait(cdm_pose &out) const;
    void set_state_flag(uint32_t flag, bool on);
    void notify_waiters();
    int finish(cdm_pose &pose, bool have, uint32_t state_before_snapshot) const;
    // Whether a pose received at host_ns (CLOCK_MONOTONIC) is older than
    // limit_ns now, by CLOCK_MONOTONIC (device_read.cpp says why not the
    // coarse clock).
    bool older_than(uint64_t host_ns, uint64_t limit_ns) const;
    static Conversion conversion_from(const cdm::proto::DeviceInfoReport &r);

    cdm::TransportPtr transport_;
    cdm_sample_fn on_sample_;
    void *user_;
    cdm_event_fn on_event_;
    cdm_rejected_fn on_rejected_;
    // Reader thread only: the STALE/FRESH edge, and the newest report's time.
    bool stale_reported_ = false;
    uint64_t last_report_ns_ = 0;
    // Tells on_event (if any) and the log.
    void emit(uint32_t kind, const std::string &text, int level);
    void check_stale();

    // Published state: read by any thread.
    cdm::SeqLock<Snapshot> snap_;
    std::atomic<uint32_t> state_flags_{0}; // DISCONNECTED, END_OF_STREAM
    std::atomic<uint32_t> stale_timeout_us_;
    std::atomic<uint64_t> events_{0}; // bumped on every publication and state change
    std::atomic<uint64_t> n_reports_{0}, n_malformed_{0}, n_dropped_{0}, n_oow_{0}, n_reconnects_{0};
    std::atomic<uint64_t> n_seq_jumps_{0}, n_out_of_order_{0}, n_restarts_{0};
    uint64_t truncated_bytes_ = 0; // set before start(), read-only after
    // host_sequence of the newest published pose (0: none yet).
    std::atomic<uint64_t> published_{0};

    // Waiters of cdm_wait_pose.
    std::atomic<int> waiters_{0};
    std::mutex wait_mu_;
    std::condition_variable wait_cv_;

    // Model handed from cdm_set_calibration to the reader thread.
    std::mutex model_mu_;
    cdm::ModelPtr pending_model_;
    bool pending_compensated_ = false;
    std::atomic<bool> model_changed_{false};

    mutable std::mutex info_mu_;
    cdm_device_info info_{};
    cdm::ModelPtr nominal_; // guarded by model_mu_ (replaced on reconnect)

    mutable std::mutex err_mu_;
    std::string error_;

    std::mutex cal_mu_; // one calibration transfer at a time

    // Reader thread's own state.
    Conversion conv_{};
    cdm::ModelPtr model_;
    bool compensated_ = false;
    bool have_last_ = false;
    uint32_t last_seq_ = 0;
    uint64_t last_host_ns_ = 0;
    uint64_t last_device_us_ = 0;
    uint64_t anchor_device_us_ = 0, anchor_host_ns_ = 0; // device_clock_trusted
    bool after_reconnect_ = false;
    // The last number before the newest jump, and when it came: a counter
    // that comes back near it (a flipped bit undone) is the jump's return,
    // not a restart.
    bool have_jump_ = false;
    uint32_t jump_from_seq_ = 0;
    uint64_t jump_from_host_ns_ = 0;
    // The newest restart counted: the number before it, when that came,
    // and the drops it booked (taken back if the counter comes back).
    struct Restart {
        uint32_t seq;
        uint64_t host_ns;
        uint64_t dropped;
    };
    bool have_restart_ = false;
    Restart restart_{};
    double last_good_p_[3] = {0, 0, 0};
    bool have_good_p_ = false;
    cdm::VelocityFilter velocity_;
    uint64_t malformed_by_kind_[8] = {};

    std::atomic<bool> stop_{false};
    // shutdown() or close: waits return CDM_ERR_CLOSED.
    std::atomic<bool> closing_{false};
    // Calls inside wait_pose / wait_pose_after (guarded by wait_mu_): the
    // destructor waits for them to leave before freeing what they read.
    int waits_in_progress_ = 0;
    // Set on the reader thread by close_from_callback: the thread frees the
    // handle when run() returns.
    bool free_on_exit_ = false;
    std::thread thread_;
    // The reader thread's id, stored by the thread itself (thread_ may still
    // be being assigned when a first callback runs): on_reader_thread.
    std::atomic<std::thread::id> reader_id_{};
};

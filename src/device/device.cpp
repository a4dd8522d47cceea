#include "device/device.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <vector>

#include "device/recording/replay_format.h"
#include "device/hid/transport_hidapi.h"
#include "io/log.h"

namespace cdm {

uint64_t monotonic_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts); // vDSO: no system call, no lock
    return uint64_t(ts.tv_sec) * 1000000000ull + uint64_t(ts.tv_nsec);
}

namespace {
void copy_str(char *dst, size_t cap, const std::string &s) {
    const size_t n = std::min(cap - 1, s.size());
    std::memcpy(dst, s.data(), n);
    dst[n] = 0;
}

ModelPtr nominal_model(const proto::DeviceInfoReport &r) {
    DeviceGeometry g;
    g.a_mm = r.a_mm;
    g.b_mm = r.b_mm;
    g.m_mm = r.m_mm;
    return std::make_shared<const Model>(g);
}
} // namespace

void device_info_from_report(const proto::DeviceInfoReport &r, const char *transport, const std::string &uri,
                             cdm_device_info &out) {
    cdm_device_info i{};
    i.struct_size = sizeof(cdm_device_info);
    i.vendor_id = proto::kVendorId;
    i.product_id = proto::kProductId;
    copy_str(i.uri, sizeof i.uri, uri);
    copy_str(i.serial, sizeof i.serial, r.serial);
    copy_str(i.firmware, sizeof i.firmware,
             std::to_string(r.fw_major) + "." + std::to_string(r.fw_minor) + "." + std::to_string(r.fw_patch));
    copy_str(i.transport, sizeof i.transport, transport);
    i.protocol_version = r.protocol_version;
    i.adc_bits = r.adc_bits;
    for (int k = 0; k < 4; ++k) {
        i.pot_scale_mm[k] = r.pot_scale_mm[k];
        i.pot_offset_mm[k] = r.pot_offset_mm[k];
    }
    i.a_mm = r.a_mm;
    i.b_mm = r.b_mm;
    i.m_mm = r.m_mm;
    i.report_rate_hz = r.report_rate_hz;
    i.hall_closed = r.hall_closed;
    i.hall_open = r.hall_open;
    i.grip_open_rad = r.grip_open_rad;
    out = i;
}

static int read_device_info(Transport &t, proto::DeviceInfoReport &info, std::string &err) {
    uint8_t buf[proto::kDeviceInfoReportSize] = {proto::kDeviceInfoReportId};
    std::string terr;
    const int n = t.get_feature(buf, sizeof buf, terr);
    if (n < 0) {
        err = "reading the device info (feature report 0x02): " + terr;
        return n;
    }
    std::string detail;
    const proto::Reject rej = proto::parse_device_info(buf, size_t(n), info, &detail);
    if (rej != proto::Reject::None) {
        err = std::string("device info (feature report 0x02, ") + std::to_string(n) +
              " bytes) rejected: " + proto::reject_text(rej) + (detail.empty() ? "" : ": " + detail);
        return CDM_ERR_PROTOCOL;
    }
    return CDM_OK;
}

int open_device(const char *uri_c, const cdm_open_options *opts, cdm_device **out, std::string &err) {
    std::string text = uri_c ? uri_c : "";
    if (text.empty()) {
        const char *env = std::getenv("CDM_DEVICE");
        if (env && *env) {
            text = env;
        } else {
            std::vector<cdm_device_info> found;
            std::string enum_err;
            hid_list_masters(found, enum_err);
            if (found.empty()) {
                err = "no URI given, $CDM_DEVICE is not set and no master (USB 1209:cd01) is connected" +
                      (enum_err.empty() ? std::string() : " (" + enum_err + ")") +
                      "; to try the simulated master, open \"sim:\"";
                return CDM_ERR_NO_DEVICE;
            }
            text = found[0].uri;
        }
    }
    Uri u;
    int rc = parse_uri(text, u, err);
    if (rc != CDM_OK) return rc;
    const TransportEntry *entry = find_transport(u.scheme);
    if (!entry) {
        std::string known;
        for (const auto &t : transports()) known += std::string(known.empty() ? "" : ", ") + t.scheme;
        err = "URI \"" + text + "\": unknown scheme \"" + u.scheme + "\" (known: " + known + ")";
        return CDM_ERR_NO_DEVICE;
    }
    TransportPtr t;
    rc = entry->open(u, t, err);
    if (rc != CDM_OK) return rc;
    proto::DeviceInfoReport info;
    rc = read_device_info(*t, info, err);
    if (rc != CDM_OK) {
        err = "URI \"" + text + "\": " + err;
        return rc;
    }
    const uint32_t stale = opts && opts->stale_timeout_us ? opts->stale_timeout_us : kDefaultStaleTimeoutUs;
    const std::string warning = t->open_warning();
    auto *dev = new cdm_device(std::move(t), info, stale, opts);
    if (!warning.empty()) dev->set_error("warning: " + warning);
    dev->start();
    *out = dev;
    return CDM_OK;
}

} // namespace cdm

using namespace cdm;

cdm_device::cdm_device(TransportPtr t, const proto::DeviceInfoReport &info, uint32_t stale_timeout_us,
                       const cdm_open_options *opts)
    : transport_(std::move(t)), on_sample_(opts ? opts->on_sample : nullptr), user_(opts ? opts->user : nullptr),
      on_event_(opts ? opts->on_event : nullptr), on_rejected_(opts ? opts->on_rejected : nullptr),
      stale_timeout_us_(stale_timeout_us) {
    truncated_bytes_ = transport_->truncated_bytes();
    device_info_from_report(info, transport_->name(), transport_->uri(), info_);
    conv_ = conversion_from(info);
    nominal_ = nominal_model(info);
    model_ = nominal_;
}

cdm_device::~cdm_device() {
    stop_.store(true);
    shutdown();
    {
        // The waits woken by shutdown() still read the handle on their way
        // out: it is freed only once the last one has left.
        std::unique_lock<std::mutex> lock(wait_mu_);
        wait_cv_.wait(lock, [&] { return waits_in_progress_ == 0; });
    }
    if (thread_.joinable()) thread_.join();
}

void cdm_device::shutdown() {
    closing_.store(true);
    notify_waiters();
    // A waiter counted in waits_in_progress_ but not yet asleep checks
    // closing_ under wait_mu_: taking it here orders the two.
    { std::lock_guard<std::mutex> lock(wait_mu_); }
    wait_cv_.notify_all();
}

void cdm_device::close_from_callback() {
    free_on_exit_ = true;
    stop_.store(true);
    shutdown();
}

void cdm_device::start() {
    thread_ = std::thread([this] {
        run();
        if (free_on_exit_) {
            // cdm_close was called on this thread (close_from_callback): no
            // callback is running any more, and nobody else will join it.
            thread_.detach();
            delete this;
        }
    });
}

cdm_device::Conversion cdm_device::conversion_from(const proto::DeviceInfoReport &r) {
    Conversion c{};
    for (int i = 0; i < 4; ++i) {
        c.scale[i] = r.pot_scale_mm[i];
        c.offset[i] = r.pot_offset_mm[i];
    }
    c.hall_closed = r.hall_closed;
    c.hall_open = r.hall_open;
    c.grip_open_rad = r.grip_open_rad;
    c.rate_hz = r.report_rate_hz;
    c.adc_full_scale = (1u << r.adc_bits) - 1u;
    return c;
}

void cdm_device::set_error(const std::string &text, int level) {
    {
        std::lock_guard<std::mutex> lock(err_mu_);
        error_ = text;
    }
    if (level >= 0) log::message(level, text);
}

void cdm_device::emit(uint32_t kind, const std::string &text, int level) {
    log::message(level, std::string(transport_->name()) + " " + transport_->uri() + ": " + text);
    // After a cdm_close from a callback or the log sink on this thread, no
    // callback starts.
    if (!on_event_ || stop_.load(std::memory_order_relaxed)) return;
    cdm_event e{};
    e.struct_size = sizeof e;
    e.kind = kind;
    e.host_time_ns = monotonic_ns();
    e.text = text.c_str();
    on_event_(user_, &e);
}

// On a read timeout: a device that has published but sent nothing for
// longer than the stale timeout goes STALE, once.
void cdm_device::check_stale() {
    if (stale_reported_ || last_report_ns_ == 0) return;
    const uint64_t limit = uint64_t(stale_timeout_us_.load(std::memory_order_relaxed)) * 1000u;
    if (monotonic_ns() - last_report_ns_ <= limit) return;
    stale_reported_ = true;
    emit(CDM_EVENT_STALE, "no report for " + std::to_string((monotonic_ns() - last_report_ns_) / 1000000u) +
                              " ms (stale timeout " + std::to_string(limit / 1000000u) + " ms)",
         log::kWarning);
}

void cdm_device::error_text(char *buf, size_t len) const {
    if (!buf || len == 0) return;
    std::lock_guard<std::mutex> lock(err_mu_);
    copy_str(buf, len, error_);
}

void cdm_device::notify_waiters() {
    events_.fetch_add(1);
    // Seq-cst pairs with the waiter's increment: either the waiter sees the
    // new event count in its predicate, or this load sees the waiter.
    if (waiters_.load() > 0) {
        { std::lock_guard<std::mutex> lock(wait_mu_); }
        wait_cv_.notify_all();
    }
}

void cdm_device::set_state_flag(uint32_t flag, bool on) {
    if (on)
        state_flags_.fetch_or(flag, std::memory_order_release);
    else
        state_flags_.fetch_and(~flag, std::memory_order_release);
}

std::string cdm_device::geometry_mismatch(const Model &model) const {
    const DeviceGeometry &g = model.geometry();
    cdm_device_info i;
    get_info(i);
    const double have[3] = {g.a_mm, g.b_mm, g.m_mm}, dev[3] = {i.a_mm, i.b_mm, i.m_mm};
    const char *names[3] = {"a_mm", "b_mm", "m_mm"};
    std::string out;
    for (int k = 0; k < 3; ++k) {
        if (std::fabs(have[k] - dev[k]) <= kGeometryToleranceMm) continue;
        char b[160];
        std::snprintf(b, sizeof b, "%s%s %.6g (calibration) vs %.6g (device %s)", out.empty() ? "" : ", ", names[k],
                      have[k], dev[k], i.serial);
        out += b;
    }
    if (out.empty()) return out;
    char tol[32];
    std::snprintf(tol, sizeof tol, "%g", kGeometryToleranceMm);
    return "the calibration is for another frame: " + out + " mm differ by more than the " + tol +
           " mm tolerance; calibrate this device, or load its own calibration";
}

void cdm_device::set_model(const ModelPtr &model) {
    std::lock_guard<std::mutex> lock(model_mu_);
    pending_model_ = model;
    pending_compensated_ = model != nullptr;
    model_changed_.store(true, std::memory_order_release);
}

void cdm_device::run() {
    reader_id_.store(std::this_thread::get_id(), std::memory_order_release);
    // Any report the replay format can hold (kMaxReport): a longer one
    // from a newer firmware is parsed for its first 64 bytes.
    uint8_t buf[replay::kMaxReport];
    while (!stop_.load(std::memory_order_relaxed)) {
        try {
            if (state_flags_.load(std::memory_order_relaxed) & CDM_POSE_DISCONNECTED) {
                if (!try_reconnect()) wait_for_arrival();
                continue;
            }
            std::string err;
            const int n = transport_->read(buf, sizeof buf, kReaderPollMs, err);
            if (n > 0) {
                // host_time_ns: the moment the transport handed the report
                // over, before parsing and the model (what the latency
                // benchmark measures from).
                handle_report(buf, size_t(n), monotonic_ns());
            } else if (n == kReadEnd) {
                set_state_flag(CDM_POSE_END_OF_STREAM, true);
                notify_waiters();
                emit(CDM_EVENT_END_OF_STREAM, "end of stream", log::kInfo);
                return;
            } else if (n == kReadTimeout) {
                check_stale();
            } else {
                const std::string why = (err.empty() ? std::string("device disconnected") : err) + "; retrying every " +
                                        std::to_string(kReconnectIntervalMs) + " ms";
                set_error(std::string(transport_->name()) + " " + transport_->uri() + ": " + why, -1);
                set_state_flag(CDM_POSE_DISCONNECTED, true);
                notify_waiters();
                emit(CDM_EVENT_DISCONNECTED, why, log::kError);
            }
        } catch (const std::exception &e) {
            // Never let one bad report or a model bug take the process down.
            set_error(std::string("reader thread: internal error: ") + e.what());
        }
    }
}

// Until the next reconnection attempt: kReconnectIntervalMs at most (the
// retry poll, kept for a device whose return no event announces: no udevd
// in a container, a transport without events, an event lost to a full
// socket), sooner when the transport reports an arrival (udev's hot-plug
// event for hid:). In slices of kReaderPollMs so that cdm_close waits no
// longer than it does while streaming.
void cdm_device::wait_for_arrival() {
    for (int waited = 0; waited < kReconnectIntervalMs && !stop_.load(); waited += kReaderPollMs)
        if (transport_->wait_arrival(std::min(kReaderPollMs, kReconnectIntervalMs - waited))) return;
}

bool cdm_device::try_reconnect() {
    std::string err;
    if (transport_->reopen(err) != CDM_OK) {
        // Every 250 ms while unplugged: the DISCONNECTED event said it once.
        set_error(std::string(transport_->name()) + " " + transport_->uri() + ": disconnected; reconnect failed: " +
                      err,
                  log::kDebug);
        return false;
    }
    proto::DeviceInfoReport info;
    if (read_device_info(*transport_, info, err) == CDM_OK) {
        // The same serial number came back, but its info may have changed
        // (a firmware update while unplugged): use what it says now.
        conv_ = conversion_from(info);
        {
            std::lock_guard<std::mutex> lock(info_mu_);
            device_info_from_report(info, transport_->name(), transport_->uri(), info_);
        }
        std::lock_guard<std::mutex> lock(model_mu_);
        const bool was_nominal = model_ == nominal_;
        nominal_ = nominal_model(info);
        if (was_nominal) model_ = nominal_;
    } else {
        set_error("reconnected, but kept the old device info: " + err);
    }
    after_reconnect_ = true;
    n_reconnects_.fetch_add(1, std::memory_order_relaxed);
    set_state_flag(CDM_POSE_DISCONNECTED, false);
    notify_waiters();
    emit(CDM_EVENT_RECONNECTED, "reconnected", log::kInfo);
    return true;
}

void cdm_device::tell_rejected(uint32_t kind, const uint8_t *buf, size_t len, uint64_t source_ns,
                               const std::string &why) {
    if (!on_rejected_ || stop_.load(std::memory_order_relaxed)) return;
    cdm_rejected r{};
    r.struct_size = sizeof r;
    r.kind = kind;
    r.report = buf;
    r.report_len = uint32_t(len);
    r.source_time_ns = source_ns;
    r.reason = why.c_str();
    on_rejected_(user_, &r);
}

std::string cdm_device::reject_report(int reason, const uint8_t *buf, size_t len) {
    const proto::Reject rej = proto::Reject(reason);
    // The reader thread is the only writer of the count: the text is stored
    // before the count rises (release), so a caller that sees the count
    // (acquire, in cdm_device_stats) also sees the text that goes with it.
    const uint64_t k = n_malformed_.load(std::memory_order_relaxed) + 1;
    ++malformed_by_kind_[size_t(rej) % 8];
    char text[200];
    std::snprintf(text, sizeof text,
                  "input report rejected (reason %d: %s): %zu bytes, report ID 0x%02x; %llu rejected so far",
                  int(rej), proto::reject_text(rej), len, len ? buf[0] : 0u, (unsigned long long)k);
    // Logged at the 1st, 10th, 100th... rejection: a flood stays readable.
    uint64_t p10 = 1;
    while (p10 * 10 <= k) p10 *= 10;
    set_error(text, k == p10 ? log::kWarning : -1);
    n_malformed_.store(k, std::memory_order_release);
    return text;
}

void cdm_device::handle_report(const uint8_t *buf, size_t len, uint64_t host_ns) {
    // A replay judges its counters by the recorded receipt times, so that
    // they come out as the recorded device's did, at any replay speed.
    const uint64_t source_ns = transport_->plays_recording() ? transport_->record_time_ns() : host_ns;
    proto::InputReport r;
    const proto::Reject rej = proto::parse_input(buf, len, r);
    if (rej != proto::Reject::None) {
        const std::string why = reject_report(int(rej), buf, len);
        tell_rejected(CDM_REJECTED_MALFORMED, buf, len, source_ns, why);
        return;
    }
    const uint32_t newest = last_seq_;
    if (!account_sequence(r.sequence, r.device_time_us, source_ns)) {
        if (on_rejected_)
            tell_rejected(CDM_REJECTED_OUT_OF_ORDER, buf, len, source_ns,
                          "sequence " + std::to_string(r.sequence) + " is the newest one's (" +
                              std::to_string(newest) + ") or up to 64 behind it: a duplicate or a late report");
        return;
    }

    if (model_changed_.load(std::memory_order_acquire)) {
        std::lock_guard<std::mutex> lock(model_mu_);
        model_ = pending_model_ ? pending_model_ : nominal_;
        compensated_ = pending_compensated_;
        model_changed_.store(false, std::memory_order_relaxed);
    }

    Snapshot s{};
    cdm_raw &raw = s.raw;
    raw.struct_size = sizeof(cdm_raw);
    raw.status = r.status;
    raw.hall_adc = r.hall_adc;
    raw.buttons = r.buttons;
    raw.sequence = r.sequence;
    raw.device_time_us = r.device_time_us;
    raw.host_time_ns = host_ns;
    for (int i = 0; i < 4; ++i) {
        raw.pot_adc[i] = r.pot_adc[i];
        raw.quat_q14[i] = r.quat_q14[i];
        raw.lengths_mm[i] = conv_.offset[i] + conv_.scale[i] * r.pot_adc[i];
    }

    cdm_pose &pose = s.pose;
    pose.struct_size = sizeof(cdm_pose);
    double p[3];
    // A saturated pot ADC (at full scale) reads a clipped count, not the
    // cable's length: no position from it.
    bool saturated = false;
    for (int i = 0; i < 4; ++i) saturated = saturated || r.pot_adc[i] >= conv_.adc_full_scale;
    const bool fresh = !saturated && model_->position(raw.lengths_mm, p) == 0 && std::isfinite(p[0]) &&
                       std::isfinite(p[1]) && std::isfinite(p[2]);
    if (fresh) {
        std::memcpy(last_good_p_, p, sizeof p);
        have_good_p_ = true;
    } else {
        pose.flags |= CDM_POSE_OUT_OF_WORKSPACE;
        // Nothing to hold yet: (0,0,0) is no position the holder ever had.
        if (!have_good_p_) pose.flags |= CDM_POSE_NO_POSITION;
        n_oow_.fetch_add(1, std::memory_order_relaxed);
    }
    std::memcpy(pose.position, last_good_p_, sizeof last_good_p_);
    velocity_.update(last_good_p_, double(r.device_time_us) * 1e-6, fresh, pose.velocity);
    if (compensated_) pose.flags |= CDM_POSE_COMPENSATED;
    double qn = 0;
    for (int i = 0; i < 4; ++i) qn += double(r.quat_q14[i]) * r.quat_q14[i];
    qn = std::sqrt(qn); // > 0: the parser rejects an all-zero quaternion
    for (int i = 0; i < 4; ++i) pose.orientation[i] = r.quat_q14[i] / qn;
    const double frac = (double(r.hall_adc) - conv_.hall_closed) / (conv_.hall_open - conv_.hall_closed);
    pose.grip = std::clamp(frac, 0.0, 1.0) * conv_.grip_open_rad;
    pose.buttons = r.buttons;
    pose.sequence = r.sequence;
    pose.device_time_us = r.device_time_us;
    pose.host_time_ns = host_ns;
    pose.dropped = uint32_t(n_dropped_.load(std::memory_order_relaxed));
    pose.host_sequence = published_.load(std::memory_order_relaxed) + 1;

    snap_.store(s);
    published_.store(pose.host_sequence); // seq-cst: pairs with the waiter count (notify_waiters)
    last_report_ns_ = host_ns;
    if (stale_reported_) {
        stale_reported_ = false;
        emit(CDM_EVENT_FRESH, "reports again", log::kInfo);
    }
    n_reports_.fetch_add(1, std::memory_order_relaxed);
    notify_waiters();

    if (on_sample_ && !stop_.load(std::memory_order_relaxed)) {
        cdm_pose cb_pose = pose;
        cb_pose.flags |= state_flags_.load(std::memory_order_relaxed);
        cdm_sample smp{};
        smp.struct_size = sizeof smp;
        smp.report_len = uint32_t(len);
        smp.report = buf;
        smp.raw = &raw;
        smp.pose = &cb_pose;
        smp.source_time_ns = source_ns;
        on_sample_(user_, &smp);
    }
}

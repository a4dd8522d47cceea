// `replay:FILE` — plays a recording made by `cdm record`, report for report,
// at its original pace (speed=1), faster or slower (speed=K), or as fast as
// the reader takes them (speed=0).
#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

#include "cdm/cdm.h"
#include "device/device.h"
#include "device/protocol.h"
#include "device/recording/replay_format.h"
#include "device/transport.h"

namespace cdm {

namespace {

// Slower than 1/1000 of real time no recording is worth watching, and the
// bound keeps every pacing computation far from overflow.
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1e6;

class ReplayTransport final : public Transport {
public:
    ReplayTransport(const std::string &uri, replay::File file, double speed)
        : uri_(uri), file_(std::move(file)), speed_(speed) {}

    int read(uint8_t *buf, size_t cap, int timeout_ms, std::string &err) override {
        if (next_ >= file_.records.size()) return kReadEnd;
        const replay::Record &r = file_.records[next_];
        if (speed_ > 0) {
            const uint64_t now = monotonic_ns();
            if (next_ == 0) start_ns_ = now;
            // In double throughout: a slow speed times a long recording may
            // exceed any integer; only a wait shorter than timeout_ms is
            // ever converted back.
            const double due_in_ns = double(r.host_ns - file_.records[0].host_ns) / speed_ - double(now - start_ns_);
            if (due_in_ns > 0) {
                if (due_in_ns > timeout_ms * 1e6) {
                    std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
                    return kReadTimeout;
                }
                std::this_thread::sleep_for(std::chrono::nanoseconds(int64_t(due_in_ns)));
            }
        }
        if (r.length > cap) {
            err = "record " + std::to_string(next_) + " longer than the read buffer";
            return kReadError;
        }
        std::memcpy(buf, file_.bytes.data() + r.offset, r.length);
        last_ns_ = r.host_ns;
        ++next_;
        return r.length;
    }

    int get_feature(uint8_t *buf, size_t len, std::string &err) override {
        if (len == 0 || file_.info.empty() || buf[0] != file_.info[0]) {
            err = "a recording holds only the device-info report (0x02)";
            return CDM_ERR_UNSUPPORTED;
        }
        const size_t n = std::min(len, file_.info.size());
        std::memcpy(buf, file_.info.data(), n);
        return int(n);
    }

    std::string open_warning() const override { return file_.warning; }
    uint64_t truncated_bytes() const override { return file_.truncated_bytes; }
    bool plays_recording() const override { return true; }
    uint64_t record_time_ns() const override { return last_ns_; }
    const char *name() const override { return "replay"; }
    std::string uri() const override { return uri_; }

private:
    std::string uri_;
    replay::File file_;
    double speed_;
    size_t next_ = 0;
    uint64_t start_ns_ = 0;
    uint64_t last_ns_ = 0;
};

} // namespace

int open_replay(const Uri &u, TransportPtr &out, std::string &err) {
    if (u.path.empty()) {
        err = "URI \"" + u.text + "\": replay: needs a file, e.g. replay:session.cdmrec";
        return CDM_ERR_INVALID_ARG;
    }
    double speed = 1.0;
    for (const auto &kv : u.options) {
        if (kv.first == "speed") {
            // 0 (as fast as read) or a factor in [kMinSpeed, kMaxSpeed].
            if (!option_double(u, kv.first, kv.second, 0.0, kMaxSpeed, speed, err) ||
                (speed != 0.0 && speed < kMinSpeed)) {
                err = "URI \"" + u.text + "\": option speed=\"" + kv.second + "\" must be 0 (as fast as possible) or " +
                      "a factor from 0.001 to 1000000";
                return CDM_ERR_INVALID_ARG;
            }
        } else {
            err = unknown_option(u, kv.first, "speed");
            return CDM_ERR_INVALID_ARG;
        }
    }
    replay::File f;
    const int rc = replay::load(u.path, f, err);
    if (rc != CDM_OK) {
        err = "URI \"" + u.text + "\": " + err;
        return rc;
    }
    proto::DeviceInfoReport info;
    std::string detail;
    const proto::Reject rej = proto::parse_device_info(f.info.data(), f.info.size(), info, &detail);
    if (rej != proto::Reject::None) {
        err = "URI \"" + u.text + "\": " + u.path + ": byte 12: device-info report rejected: " +
              proto::reject_text(rej) + (detail.empty() ? "" : ": " + detail);
        return CDM_ERR_PARSE;
    }
    out = std::make_unique<ReplayTransport>(u.text, std::move(f), speed);
    return CDM_OK;
}

} // namespace cdm

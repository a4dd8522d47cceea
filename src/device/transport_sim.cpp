// `sim:` — the in-process simulated master. It emulates the firmware (the
// same byte-exact input and feature reports as the real device, through the
// same serializer) on top of a physical model of the device, so everything
// above the transport runs exactly as with the hardware.
#include <chrono>
#include <cstring>
#include <deque>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "cdm/cdm.h"
#include "device/device.h"
#include "device/sim/faults.h"
#include "device/sim/firmware.h"
#include "device/sim/sim_truth.h"
#include "device/sim/simulator.h"
#include "device/transport.h"
#include "jig/planned.h"
#include "io/calibration_json.h"
#include "io/device_json.h"
#include "io/file.h"

namespace cdm {

namespace {

constexpr const char *kSimOptions =
    "rate, noise, imu_noise, hall_noise, seed, motion, effects, effect_seed, device, truth, realtime, "
    "stall_after, serial, jig_n, jig_pitch, jig_heights, jig_samples, jig_tolerance, jig_transit, jig_plan";

// Reports the host has not read pile up in the kernel's hidraw queue (64
// reports on Linux); beyond that the oldest are lost. A paced simulation
// whose reader falls further behind than that skips, exactly like the device.
constexpr uint64_t kHostQueueReports = 64;

class SimTransport final : public Transport {
public:
    SimTransport(const std::string &uri, ModelPtr truth, const proto::DeviceInfoReport &info,
                 std::unique_ptr<sim::Motion> motion, const sim::SensorOptions &so, bool realtime,
                 uint64_t stall_after, sim::FaultPlan faults)
        : uri_(uri), fw_(info), sim_(std::move(truth), fw_, std::move(motion), so), rate_hz_(so.rate_hz),
          realtime_(realtime), stall_after_(stall_after), faults_(std::move(faults), so.rate_hz),
          history_(kSimTruthHistory) {}

    int read(uint8_t *buf, size_t cap, int timeout_ms, std::string &err) override {
        if (cap < proto::kInputReportSize) return kReadError;
        if (unplugged_) return kReadDisconnected;
        if (!pending_.empty()) return deliver(buf);
        if (ended_) return kReadEnd;
        const int n = produce(buf, timeout_ms);
        if (n <= 0 || !faults_.active()) return n;
        const uint64_t k = produced_ - 1;
        if (const uint64_t ms = faults_.disconnect_at(k)) {
            // Unplugged: this report and those the device samples meanwhile
            // never reach the host; reopen() succeeds after ms (same serial).
            unplugged_ = true;
            replug_ns_ = monotonic_ns() + ms * 1000000u;
            err = "simulated unplug at report " + std::to_string(k) + " for " + std::to_string(ms) + " ms";
            return kReadDisconnected;
        }
        faults_.process(k, buf, size_t(n), pending_);
        return pending_.empty() ? int(kReadTimeout) : deliver(buf);
    }

    int reopen(std::string &err) override {
        if (!unplugged_) return CDM_OK;
        if (monotonic_ns() < replug_ns_) {
            err = "simulated master still unplugged";
            return CDM_ERR_NO_DEVICE;
        }
        unplugged_ = false;
        return CDM_OK;
    }

private:
    int deliver(uint8_t *buf) {
        const std::vector<uint8_t> r = std::move(pending_.front());
        pending_.pop_front();
        std::memcpy(buf, r.data(), r.size());
        return int(r.size());
    }

    // One report of the simulated firmware, paced when realtime.
    int produce(uint8_t *buf, int timeout_ms) {
        if (stall_after_ && produced_ >= stall_after_) {
            // A hung device: connected, silent.
            std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
            return kReadTimeout;
        }
        if (realtime_) {
            const uint64_t now = monotonic_ns();
            if (!started_) {
                start_ns_ = now;
                started_ = true;
            }
            const double period_ns = 1e9 / rate_hz_;
            const uint64_t due = start_ns_ + uint64_t(double(sim_.index()) * period_ns);
            if (now < due) {
                if (double(due - now) > timeout_ms * 1e6) {
                    std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
                    return kReadTimeout;
                }
                std::this_thread::sleep_for(std::chrono::nanoseconds(due - now));
            } else {
                const uint64_t behind = uint64_t(double(now - due) / period_ns);
                if (behind > kHostQueueReports) sim_.skip(behind - kHostQueueReports);
            }
        }
        SimTruth t;
        if (!sim_.next(buf, t)) {
            ended_ = true;
            return kReadEnd;
        }
        ++produced_;
        {
            std::lock_guard<std::mutex> lock(history_mu_);
            history_[t.sequence % kSimTruthHistory] = t;
        }
        return int(proto::kInputReportSize);
    }

public:
    int get_feature(uint8_t *buf, size_t len, std::string &err) override {
        const int n = fw_.get_feature(buf, len);
        if (n < 0) {
            err = "simulated firmware refused GET feature report " + report_id_text(buf[0]);
            return CDM_ERR_IO;
        }
        return n;
    }

    int send_feature(const uint8_t *buf, size_t len, std::string &err) override {
        if (fw_.send_feature(buf, len) < 0) {
            err = "simulated firmware refused SET feature report " + report_id_text(len ? buf[0] : 0);
            return CDM_ERR_IO;
        }
        return CDM_OK;
    }

    const char *name() const override { return "sim"; }
    std::string uri() const override { return uri_; }

    bool truth(uint32_t seq, SimTruth &out) {
        std::lock_guard<std::mutex> lock(history_mu_);
        const SimTruth &t = history_[seq % kSimTruthHistory];
        if (t.sequence != seq || (seq == 0 && produced_ == 0)) return false;
        out = t;
        return true;
    }

private:

    std::string uri_;
    sim::Firmware fw_;
    sim::Simulator sim_;
    double rate_hz_;
    bool realtime_;
    uint64_t stall_after_;
    sim::FaultInjector faults_;
    std::deque<std::vector<uint8_t>> pending_; // reports due to the host after fault injection
    bool unplugged_ = false;
    uint64_t replug_ns_ = 0;
    bool started_ = false, ended_ = false;
    uint64_t start_ns_ = 0;
    std::atomic<uint64_t> produced_{0};
    std::mutex history_mu_; // reader thread writes, sim_truth readers read
    std::vector<SimTruth> history_;
};

} // namespace

namespace {

// A sim: URI's options.
struct SimOptions {
    sim::SensorOptions so;
    std::string motion = "random", effects, device_path, truth_path, serial = "CDMSIM0001";
    bool realtime = true, have_effect_seed = false;
    uint64_t effect_seed = 0, stall_after = 0;
    sim::FaultPlan faults;
    sim::JigMotionOptions jig;
    bool any_jig_option = false;
    std::vector<PlanRow> jig_plan; // jig_plan=PLAN.csv's rows
};

// One jig_* option into o.jig; false + err when its value is refused.
bool jig_option(const Uri &u, const std::string &k, const std::string &v, SimOptions &o, std::string &err) {
    uint64_t n = 0;
    bool ok = true;
    o.any_jig_option = true;
    if (k == "jig_n") {
        ok = option_u64(u, k, v, 1, 1000, n, err);
        o.jig.plan.n = int(n);
    } else if (k == "jig_pitch") {
        ok = option_double(u, k, v, 1e-3, 1000.0, o.jig.plan.pitch_mm, err);
    } else if (k == "jig_heights") {
        std::string herr;
        ok = parse_heights(v, o.jig.plan.heights_mm, herr);
        if (!ok) err = "URI \"" + u.text + "\": option " + herr;
    } else if (k == "jig_samples") {
        ok = option_u64(u, k, v, 1, 1000000, n, err);
        o.jig.plan.samples = int(n);
    } else if (k == "jig_tolerance") {
        ok = option_double(u, k, v, 0.0, 10.0, o.jig.tolerance_mm, err);
    } else if (k == "jig_plan") {
        std::string perr;
        ok = read_plan_csv(v, o.jig_plan, perr);
        if (!ok) err = "URI \"" + u.text + "\": option jig_plan: " + perr;
    } else { // jig_transit
        ok = option_u64(u, k, v, 1, 100000, n, err);
        o.jig.transit = int(n);
    }
    return ok;
}

// The URI's options into o: CDM_OK, or an error code and err naming the
// option and what is wrong with it.
int parse_sim_options(const Uri &u, SimOptions &o, std::string &err) {
    if (!u.path.empty()) {
        err = "URI \"" + u.text + "\": sim: takes options after '?', e.g. sim:?rate=500&noise=0.1";
        return CDM_ERR_INVALID_ARG;
    }
    for (const auto &kv : u.options) {
        const std::string &k = kv.first, &v = kv.second;
        bool ok = true;
        if (k == "rate") ok = option_double(u, k, v, 1.0, 100000.0, o.so.rate_hz, err);
        else if (k == "noise") ok = option_double(u, k, v, 0.0, 100.0, o.so.noise_mm, err);
        else if (k == "imu_noise") ok = option_double(u, k, v, 0.0, 1.0, o.so.imu_noise_rad, err);
        else if (k == "hall_noise") ok = option_double(u, k, v, 0.0, 4095.0, o.so.hall_noise, err);
        else if (k == "seed") ok = option_u64(u, k, v, 0, UINT64_MAX, o.so.seed, err);
        else if (k == "effect_seed") ok = o.have_effect_seed = option_u64(u, k, v, 0, UINT64_MAX, o.effect_seed, err);
        else if (k == "stall_after") ok = option_u64(u, k, v, 1, UINT64_MAX, o.stall_after, err);
        else if (k == "realtime") {
            ok = v == "0" || v == "1";
            o.realtime = v == "1";
            if (!ok) err = "URI \"" + u.text + "\": option realtime=\"" + v + "\" must be 0 or 1";
        } else if (k == "motion") {
            ok = v == "random" || v == "still" || v == "circle" || v == "jig";
            o.motion = v;
            if (!ok) err = "URI \"" + u.text + "\": option motion=\"" + v + "\" must be random, still, circle or jig";
        } else if (k == "effects") o.effects = v;
        else if (k == "device") o.device_path = v;
        else if (k == "truth") o.truth_path = v;
        else if (k == "serial") {
            ok = !v.empty() && v.size() <= 16 && v.find_first_not_of(
                "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_.") == std::string::npos;
            o.serial = v;
            if (!ok) err = "URI \"" + u.text + "\": option serial=\"" + v + "\" must be 1..16 of [A-Za-z0-9-_.]";
        } else if (k == "jig_n" || k == "jig_pitch" || k == "jig_heights" || k == "jig_samples" ||
                   k == "jig_tolerance" || k == "jig_transit" || k == "jig_plan") {
            ok = jig_option(u, k, v, o, err);
        } else {
            bool known = false;
            ok = sim::parse_fault_option(u, k, v, o.faults, known, err);
            if (!known) {
                err = unknown_option(u, k, (std::string(kSimOptions) + ", " + sim::kFaultOptions).c_str());
                return CDM_ERR_INVALID_ARG;
            }
        }
        if (!ok) return CDM_ERR_INVALID_ARG;
    }
    if (o.any_jig_option && o.motion != "jig") {
        err = "URI \"" + u.text + "\": jig_* options need motion=jig";
        return CDM_ERR_INVALID_ARG;
    }
    if (!o.device_path.empty() && !o.truth_path.empty()) {
        err = "URI \"" + u.text + "\": give device= or truth= (which carries its own geometry), not both";
        return CDM_ERR_INVALID_ARG;
    }
    return CDM_OK;
}

// The physical truth: nominal geometry, or a calibration's model, plus
// any hidden effects. CDM_OK, or an error code and err.
int load_truth(const Uri &u, const SimOptions &o, std::shared_ptr<Model> &model, std::string &err) {
    DeviceGeometry g;
    if (!o.device_path.empty()) {
        std::string text;
        if (!io::read_file(o.device_path, io::kJsonMaxBytes, text, err, "device description")) {
            err = "URI \"" + u.text + "\": option device: " + err;
            return CDM_ERR_INVALID_ARG;
        }
        if (!io::parse_device_json(text, o.device_path, g, err)) {
            err = "URI \"" + u.text + "\": option device: " + err;
            return CDM_ERR_PARSE;
        }
        model = std::make_shared<Model>(g);
    } else if (!o.truth_path.empty()) {
        model = std::make_shared<Model>(g);
        std::string text;
        if (!io::read_file(o.truth_path, io::kJsonMaxBytes, text, err, "calibration")) {
            err = "URI \"" + u.text + "\": option truth: " + err;
            return CDM_ERR_INVALID_ARG;
        }
        if (!io::parse_calibration_json(text, o.truth_path, *model, err)) {
            err = "URI \"" + u.text + "\": option truth: " + err;
            return CDM_ERR_PARSE;
        }
    } else {
        model = std::make_shared<Model>(g);
    }
    if (o.effects.empty()) return CDM_OK;
    const uint64_t effect_seed = o.have_effect_seed ? o.effect_seed : o.so.seed;
    size_t start = 0, index = 0;
    while (start <= o.effects.size()) {
        size_t end = o.effects.find(',', start);
        if (end == std::string::npos) end = o.effects.size();
        const std::string name = o.effects.substr(start, end - start);
        std::string eerr;
        if (name.empty() || !model->add_effect_random(name, effect_seed + index, eerr)) {
            err = "URI \"" + u.text + "\": option effects: \"" + name + "\": " +
                  (eerr.empty() ? "empty effect name" : eerr);
            return CDM_ERR_INVALID_ARG;
        }
        ++index;
        start = end + 1;
    }
    return CDM_OK;
}

// What the firmware says about itself: the 16-bit ADC at 0.01 mm per
// count from 0 mm (0..655.35 mm covers every cable length of the
// default frame), a 12-bit Hall sensor whose field falls as the jaw
// opens, and the nominal geometry (hidden effects are, by definition,
// not in the device info).
proto::DeviceInfoReport sim_device_info(const SimOptions &o, const DeviceGeometry &tg) {
    proto::DeviceInfoReport info;
    info.fw_major = 1;
    info.fw_minor = 0;
    info.fw_patch = 0;
    info.adc_bits = 16;
    std::snprintf(info.serial, sizeof info.serial, "%s", o.serial.c_str());
    info.report_rate_hz = float(o.so.rate_hz);
    for (int i = 0; i < 4; ++i) {
        info.pot_scale_mm[i] = 0.01f;
        info.pot_offset_mm[i] = 0.0f;
    }
    info.a_mm = float(tg.a_mm);
    info.b_mm = float(tg.b_mm);
    info.m_mm = float(tg.m_mm);
    info.hall_closed = 2600;
    info.hall_open = 1400;
    info.grip_open_rad = 0.6f;
    return info;
}

} // namespace

int open_sim(const Uri &u, TransportPtr &out, std::string &err) {
    SimOptions o;
    if (const int rc = parse_sim_options(u, o, err); rc != CDM_OK) return rc;
    std::shared_ptr<Model> model;
    if (const int rc = load_truth(u, o, model, err); rc != CDM_OK) return rc;
    ModelPtr truth = model;
    const proto::DeviceInfoReport info = sim_device_info(o, truth->geometry());
    std::unique_ptr<sim::Motion> m;
    if (o.motion == "random") m = sim::make_random_motion(o.so.seed ^ 0x9E3779B97F4A7C15ull, info.grip_open_rad);
    else if (o.motion == "still") m = sim::make_still_motion();
    else if (o.motion == "circle") m = sim::make_circle_motion(info.grip_open_rad);
    else {
        std::string jerr;
        if (!check_jig_options(o.jig.plan, jerr)) {
            err = "URI \"" + u.text + "\": " + jerr;
            return CDM_ERR_INVALID_ARG;
        }
        sim::JigMotionOptions jig = o.jig;
        jig.seed = o.so.seed ^ 0x6A09E667F3BCC909ull;
        if (!o.jig_plan.empty() && !match_plan(make_jig_plan(o.jig.plan), o.jig_plan, jig.visits, jerr)) {
            err = "URI \"" + u.text + "\": jig_plan: " + jerr;
            return CDM_ERR_INVALID_ARG;
        }
        m = sim::make_jig_motion(truth, jig);
    }
    out = std::make_unique<SimTransport>(u.text, truth, info, std::move(m), o.so, o.realtime, o.stall_after,
                                         std::move(o.faults));
    return CDM_OK;
}

bool sim_truth(cdm_device *dev, uint32_t seq, SimTruth &out) {
    if (!dev) return false;
    auto *s = dynamic_cast<SimTransport *>(&dev->transport());
    return s && s->truth(seq, out);
}

bool sim_truth(cdm_device *dev, uint32_t seq, double position[3]) {
    SimTruth t;
    if (!sim_truth(dev, seq, t)) return false;
    for (int i = 0; i < 3; ++i) position[i] = t.position[i];
    return true;
}

} // namespace cdm

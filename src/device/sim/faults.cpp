#include "device/sim/faults.h"

#include <cstring>

#include "device/protocol.h"

namespace cdm::sim {

const char *const kFaultOptions =
    "drop, duplicate, reorder, malformed, seq_reset, seq_flip, clock_wrap, saturate, disconnect";

bool FaultPlan::any() const {
    return !drop.empty() || !duplicate.empty() || !reorder.empty() || !seq_flip.empty() || !malformed.empty() ||
           seq_reset || clock_wrap || saturate_count || !disconnect_ms.empty();
}

namespace {

// "a,b,c" -> items; each item checked by the caller.
std::vector<std::string> split(const std::string &v, char sep) {
    std::vector<std::string> out;
    size_t start = 0;
    for (;;) {
        const size_t p = v.find(sep, start);
        out.push_back(v.substr(start, p == std::string::npos ? std::string::npos : p - start));
        if (p == std::string::npos) return out;
        start = p + 1;
    }
}

bool index_list(const Uri &u, const std::string &k, const std::string &v, std::set<uint64_t> &out,
                std::string &err) {
    for (const std::string &item : split(v, ',')) {
        uint64_t n = 0;
        if (!option_u64(u, k, item, 0, uint64_t(1) << 40, n, err)) {
            err += " (a comma-separated list of report indices)";
            return false;
        }
        out.insert(n);
    }
    return true;
}

// "A:B" -> two numbers.
bool pair_of(const Uri &u, const std::string &k, const std::string &item, uint64_t &a, uint64_t &b, uint64_t b_lo,
             uint64_t b_hi, const char *form, std::string &err) {
    const auto parts = split(item, ':');
    if (parts.size() != 2 || !option_u64(u, k, parts[0], 0, uint64_t(1) << 40, a, err) ||
        !option_u64(u, k, parts[1], b_lo, b_hi, b, err)) {
        err = "URI \"" + u.text + "\": option " + k + "=\"" + item + "\" must be " + form;
        return false;
    }
    return true;
}

} // namespace

bool parse_fault_option(const Uri &u, const std::string &k, const std::string &v, FaultPlan &plan, bool &known,
                        std::string &err) {
    known = true;
    if (k == "drop") return index_list(u, k, v, plan.drop, err);
    if (k == "duplicate") return index_list(u, k, v, plan.duplicate, err);
    if (k == "reorder") return index_list(u, k, v, plan.reorder, err);
    if (k == "seq_flip") return index_list(u, k, v, plan.seq_flip, err);
    if (k == "seq_reset") return plan.seq_reset = option_u64(u, k, v, 1, uint64_t(1) << 40, plan.seq_reset_at, err);
    if (k == "clock_wrap")
        return plan.clock_wrap = option_u64(u, k, v, 1, uint64_t(1) << 40, plan.clock_wrap_at, err);
    if (k == "saturate")
        return pair_of(u, k, v, plan.saturate_at, plan.saturate_count, 1, uint64_t(1) << 40, "AT:COUNT", err);
    if (k == "disconnect") {
        for (const std::string &item : split(v, ',')) {
            uint64_t at = 0, ms = 0;
            if (!pair_of(u, k, item, at, ms, 1, 600000, "AT:MS[,AT:MS...] (MS 1..600000)", err)) return false;
            plan.disconnect_ms[at] = ms;
        }
        return true;
    }
    if (k == "malformed") {
        static const std::map<std::string, Malform> kinds = {{"short", Malform::Short},
                                                             {"report_id", Malform::ReportId},
                                                             {"version", Malform::Version},
                                                             {"quat_zero", Malform::QuatZero},
                                                             {"quat_norm", Malform::QuatNorm}};
        for (const std::string &item : split(v, ',')) {
            const auto parts = split(item, ':');
            uint64_t at = 0;
            const auto kind = parts.size() == 2 ? kinds.find(parts[0]) : kinds.end();
            if (kind == kinds.end() || !option_u64(u, k, parts[1], 0, uint64_t(1) << 40, at, err)) {
                err = "URI \"" + u.text + "\": option malformed=\"" + item +
                      "\" must be KIND:AT with KIND short, report_id, version, quat_zero or quat_norm";
                return false;
            }
            plan.malformed[at] = kind->second;
        }
        return true;
    }
    known = false;
    return true;
}

uint64_t FaultInjector::disconnect_at(uint64_t k) const {
    const auto it = plan_.disconnect_ms.find(k);
    return it == plan_.disconnect_ms.end() ? 0 : it->second;
}

void FaultInjector::process(uint64_t k, const uint8_t *report, size_t len, std::deque<std::vector<uint8_t>> &out) {
    std::vector<uint8_t> r(report, report + len);
    uint32_t seq = proto::get_u32(r.data() + 4);
    if (plan_.seq_reset && k >= plan_.seq_reset_at) {
        // The firmware restarted its counter (a brown-out) at report k.
        if (!have_seq_base_) seq_base_ = seq, have_seq_base_ = true;
        seq -= seq_base_;
    }
    if (plan_.seq_flip.count(k)) seq ^= 1u << 30; // one corrupted bit
    proto::put_u32(r.data() + 4, seq);
    if (plan_.clock_wrap) {
        // The device clock passes 2^64 us just before report clock_wrap_at.
        const uint64_t t_at = uint64_t(double(plan_.clock_wrap_at) * 1e6 / rate_hz_);
        proto::put_u64(r.data() + 8, proto::get_u64(r.data() + 8) - t_at);
    }
    if (plan_.saturate_count && k >= plan_.saturate_at && k - plan_.saturate_at < plan_.saturate_count)
        for (int i = 0; i < 4; ++i) proto::put_u16(r.data() + 16 + 2 * i, 0xFFFF); // ADC at full scale
    const auto m = plan_.malformed.find(k);
    if (m != plan_.malformed.end()) {
        switch (m->second) {
        case Malform::Short: r.resize(10); break;
        case Malform::ReportId: r[0] = 0x7E; break;
        case Malform::Version: r[1] = 0xEE; break;
        case Malform::QuatZero: std::memset(r.data() + 24, 0, 8); break;
        case Malform::QuatNorm: proto::put_u16(r.data() + 26, 16384); break; // w = x = 1: |q| = sqrt(2)
        }
    }
    std::vector<std::vector<uint8_t>> emit;
    if (!plan_.drop.count(k)) emit.push_back(r);
    if (plan_.duplicate.count(k)) emit.push_back(r);
    if (plan_.reorder.count(k) && !emit.empty()) {
        held_ = emit.back(); // delivered after report k+1
        emit.pop_back();
    } else if (!held_.empty()) {
        emit.push_back(std::move(held_));
        held_.clear();
    }
    for (auto &e : emit) out.push_back(std::move(e));
}

} // namespace cdm::sim

// Fault injection for `sim:` (docs/protocol.md, "Fault injection";
// docs/reliability.md has the table of what the caller sees). Faults are
// scheduled by report index k (0 = the first report; time = k / rate), so a
// test knows exactly which report is hit, paced or not.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "device/transport.h"

namespace cdm::sim {

enum class Malform { Short, ReportId, Version, QuatZero, QuatNorm };

struct FaultPlan {
    std::set<uint64_t> drop, duplicate, reorder, seq_flip;
    std::map<uint64_t, Malform> malformed;
    bool seq_reset = false;
    uint64_t seq_reset_at = 0;
    bool clock_wrap = false;
    uint64_t clock_wrap_at = 0;
    uint64_t saturate_at = 0, saturate_count = 0; // count 0: none
    std::map<uint64_t, uint64_t> disconnect_ms;   // at report k, unplugged for ms
    bool any() const;
};

// The option names this module knows, for the sim: usage text.
extern const char *const kFaultOptions;

// Parses one sim: option into the plan. Returns false with err set on a bad
// value; sets `known` to whether the key is a fault option at all.
bool parse_fault_option(const Uri &u, const std::string &key, const std::string &value, FaultPlan &plan,
                        bool &known, std::string &err);

class FaultInjector {
public:
    FaultInjector(FaultPlan plan, double rate_hz) : plan_(std::move(plan)), rate_hz_(rate_hz) {}
    bool active() const { return plan_.any(); }
    // Milliseconds the device stays unplugged from report k on, or 0.
    uint64_t disconnect_at(uint64_t k) const;
    // Report k (kInputReportSize bytes) as the host receives it: appended to
    // `out` as 0 (dropped), 1 or 2 (duplicated) reports; a reordered report
    // is held back and delivered after report k+1.
    void process(uint64_t k, const uint8_t *report, size_t len, std::deque<std::vector<uint8_t>> &out);

private:
    FaultPlan plan_;
    double rate_hz_;
    uint32_t seq_base_ = 0;
    bool have_seq_base_ = false;
    std::vector<uint8_t> held_; // a reordered report waiting for its successor
};

} // namespace cdm::sim

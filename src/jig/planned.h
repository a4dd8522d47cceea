// A planned jig session (`cdm calib plan`): the PLAN.csv it writes, read
// back, and its rows matched to the plate's positions. Shared by the
// dataset simulator (`cdm calib simulate --plan`), the simulated master
// (`sim:?motion=jig&jig_plan=PLAN.csv`) and the recorder (`cdm record --jig
// --plan`), so that all three visit the same holes in the same order.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "jig/plan.h"

namespace cdm {

// x_ref, y_ref, z_ref (mm, the jig frame) and the samples to take there.
using PlanRow = std::array<double, 4>;

// The file's header line.
extern const char *const kPlanHeader;
// Largest PLAN.csv read: ~500,000 positions.
constexpr size_t kPlanMaxBytes = size_t(16) << 20;

// Reads PLAN.csv: a regular file, the header, then one row per position of
// four numbers (references within +-5000 mm, samples a whole number in
// 1..1000000), at least one. False + err "PATH:LINE: what" (or "PATH is
// ...") on the first fault.
bool read_plan_csv(const std::string &path, std::vector<PlanRow> &rows, std::string &err);

// One visit of a planned session: a position of the plate plan and the
// samples to take there.
struct PlannedVisit {
    size_t index; // into the plate plan (make_jig_plan)
    int samples;
};

// The plate position each row is (its reference within 1e-6 mm of one
// hole at one height), in the rows' order. False + err naming the first row
// that is not ("plan position K (x, y, z mm) is not a hole of the plate at
// one of its heights") or whose samples are not a whole number in 1..1e6.
bool match_plan(const std::vector<JigPosition> &plate, const std::vector<PlanRow> &rows,
                std::vector<PlannedVisit> &visits, std::string &err);

} // namespace cdm

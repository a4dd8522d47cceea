#include "calib/dataset/simulate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>

#include "jig/errors.h"
#include "jig/planned.h"

namespace cdm {

namespace {

// The positions to simulate: the whole plan, or o.plan's rows matched to
// the plan's positions.
bool planned_visits(const std::vector<JigPosition> &plan, const JigSimOptions &o,
                    std::vector<std::pair<size_t, int>> &visits, std::string &err) {
    if (o.plan.empty()) {
        for (size_t k = 0; k < plan.size(); ++k) visits.emplace_back(k, o.samples);
        return true;
    }
    if (o.scattered) {
        err = "a planned session is on the plate's holes, not a scattered layout";
        return false;
    }
    std::vector<PlannedVisit> planned;
    if (!match_plan(plan, o.plan, planned, err)) return false;
    for (const PlannedVisit &v : planned) visits.emplace_back(v.index, v.samples);
    return true;
}

// The plate of the simulator's options.
JigPlanOptions plate_of(const JigSimOptions &o) {
    JigPlanOptions po;
    po.n = o.n;
    po.pitch_mm = o.pitch_mm;
    po.heights_mm = o.heights;
    po.samples = o.samples;
    return po;
}

template <class Sink> bool run(const Model &truth, const JigSimOptions &o, Sink sink, std::string &err) {
    const JigPlanOptions po = plate_of(o);
    if (!check_jig_options(po, err)) return false;
    const auto plan = o.scattered ? make_scattered_plan(po, o.seed ^ 0x3C6EF372FE94F82Bull) : make_jig_plan(po);
    JigErrorOptions je;
    je.hole_mm = o.jig_hole_mm;
    je.fixture_mm = o.jig_fixture_mm;
    je.seat_mm = o.jig_tolerance_mm;
    je.seed = o.seed ^ 0xBB67AE8584CAA73Bull;
    const auto where = jig_true_positions(plan, o.n, je);
    std::vector<std::pair<size_t, int>> visits; // (plan index, samples), in the order walked
    if (!planned_visits(plan, o, visits, err)) return false;
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<double> g(0.0, 1.0);
    size_t row = 0; // data rows written so far: a row's time is row * kDatasetNominalRowPeriodS
    for (const auto &[k, samples] : visits) {
        double p[3], L[4], L1[4];
        truth.jig_to_device(where[k].data(), p);
        // Readings at the position's first and last sample time: an effect
        // that drifts in time (pot_drift) moves them; between the two they
        // are interpolated linearly (exact for a linear drift; the common
        // curvature's error over one position's samples is below 1e-8 mm).
        const double t0 = double(row) * kDatasetNominalRowPeriodS;
        const double t1 = double(row + size_t(std::max(0, samples - 1))) * kDatasetNominalRowPeriodS;
        if (truth.readings(p, t0, L) != 0 || truth.readings(p, t1, L1) != 0) {
            err = "a user effect of the true model failed at point " + std::to_string(plan[k].point);
            return false;
        }
        for (int c = 0; c < 4; ++c)
            if (!std::isfinite(L[c]) || !std::isfinite(L1[c])) {
                err = "simulated readings are not finite at point " + std::to_string(plan[k].point);
                return false;
            }
        for (int s = 0; s < samples; ++s, ++row) {
            double l[4];
            const double f = samples > 1 ? double(s) / double(samples - 1) : 0.0;
            for (int c = 0; c < 4; ++c) {
                l[c] = L[c] + f * (L1[c] - L[c]) + o.noise_mm * g(rng);
                if (o.quant_mm > 0) l[c] = std::round(l[c] / o.quant_mm) * o.quant_mm;
            }
            sink(long(plan[k].point), plan[k].ref, l);
        }
    }
    return true;
}
} // namespace

bool check_jig_sim(const JigSimOptions &o, std::string &err) {
    const JigPlanOptions po = plate_of(o);
    if (!check_jig_options(po, err)) return false;
    if (o.plan.empty()) return true;
    std::vector<std::pair<size_t, int>> visits;
    return planned_visits(make_jig_plan(po), o, visits, err);
}

bool simulate_jig_csv(const Model &truth, const JigSimOptions &o, const std::string &path,
                      const std::vector<std::string> &protect_paths, std::string &err) {
    // Rows stream into the writer's temporary: memory stays flat however
    // large the simulated session.
    DatasetWriter w;
    if (!w.open(path, protect_paths, err)) return false;
    bool ok = true;
    if (!run(truth, o, [&](long id, const double *r, const double *l) { ok = ok && w.add_row(id, r, l, err); }, err))
        return false;
    return ok && w.commit(err);
}

bool simulate_jig(const Model &truth, const JigSimOptions &o, Dataset &out, std::string &err) {
    std::string text = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    char buf[256];
    if (!run(truth, o,
             [&](long id, const double *r, const double *l) {
                 std::snprintf(buf, sizeof buf, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", id, r[0], r[1], r[2], l[0],
                               l[1], l[2], l[3]);
                 text += buf;
             },
             err))
        return false;
    return parse_dataset(text, "(simulated)", out, err);
}

} // namespace cdm

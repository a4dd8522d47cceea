// The accuracy map against the truth: over independent noise draws of one
// simulated device and jig, the 95 % ellipsoid of each grid point (the fit's
// covariance propagated to the position, calib/evaluation/accuracy.h) is
// compared with the refitted model's true error there (the truth's readings
// at the point, placed by the fitted model). A calibrated uncertainty
// covers it at about 95 % of the points; the band is 90-98 %,
// inside the jig's volume and outside it (extrapolated) alike.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <setjmp.h>
#include <string>

#include "calib/calibration/fit_calibration.h"
#include "calib/dataset/simulate.h"
#include "calib/evaluation/accuracy.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

namespace {

struct Coverage {
    long in = 0, in_hit = 0, out = 0, out_hit = 0;
};

// One draw: the session simulated with noise seed `seed`, fitted with the
// true effects, its map scored against the truth.
void one_draw(const Model &truth, const std::vector<std::string> &effects, JigSimOptions o, uint64_t seed,
              Coverage &c) {
    o.seed = seed;
    Dataset d;
    std::string err;
    if (!simulate_jig(truth, o, d, err)) fail_msg("simulate: %s", err.c_str());
    FitCalibrationOptions fo;
    fo.effects = effects;
    fo.threads = 1;
    CalibrationFit cf(truth.geometry());
    if (!fit_calibration(d, truth.geometry(), fo, cf, err)) fail_msg("fit: %s", err.c_str());
    diag::AccuracyMap am;
    if (!diag::accuracy_map(cf.model, cf.report, cf.pos, cf.grid, am, err)) fail_msg("map: %s", err.c_str());
    for (size_t j = 0; j < am.p.size(); ++j) {
        if (!am.ok[j]) continue;
        double l[4], q[3];
        const double p[3] = {am.p[j](0), am.p[j](1), am.p[j](2)};
        if (truth.readings(p, am.t_s, l) != 0 || cf.model.position(l, am.t_s, q, nullptr) != 0) continue;
        const Eigen::Vector3d e(q[0] - p[0], q[1] - p[1], q[2] - p[2]);
        const bool hit = e.dot(am.cov[j].ldlt().solve(e)) <= diag::kChi2Of3At95;
        (am.inside[j] ? c.in : c.out) += 1;
        (am.inside[j] ? c.in_hit : c.out_hit) += hit;
    }
}

void covers(const char *name, const std::vector<std::string> &effects, const JigSimOptions &o, int draws) {
    Model truth{DeviceGeometry{}};
    std::string err;
    for (size_t k = 0; k < effects.size(); ++k)
        if (!truth.add_effect_random(effects[k], 7 + k, err)) fail_msg("%s", err.c_str());
    Coverage c;
    for (int k = 0; k < draws; ++k) one_draw(truth, effects, o, 1000 + uint64_t(k), c);
    const double in = double(c.in_hit) / double(c.in), out = double(c.out_hit) / double(c.out);
    std::printf("%s: 95 %% ellipsoids cover the true error at %.3f of %ld points inside the jig, %.3f of %ld "
                "outside (%d draws)\n",
                name, in, c.in, out, c.out, draws);
    assert_true(c.in > 0 && c.out > 0);
    assert_true(in >= 0.90 && in <= 0.98);
    assert_true(out >= 0.90 && out <= 0.98);
}

JigSimOptions small_jig() {
    JigSimOptions o;
    o.n = 7;
    o.pitch_mm = 15;
    o.heights = {30, 45, 60, 75};
    o.samples = 10;
    return o;
}

void exit_pulley_and_gains(void **) { covers("exit_pulley + cable_gain", {"exit_pulley", "cable_gain"}, small_jig(), 100); }

void anchors_on_a_noisy_jig(void **) {
    JigSimOptions o = small_jig();
    o.jig_tolerance_mm = 0.06;
    covers("anchor_position, jig 0.06 mm", {"anchor_position"}, o, 100);
}

void a_plate_with_hole_and_fixture_errors(void **) {
    JigSimOptions o = small_jig();
    o.jig_tolerance_mm = 0.02;
    o.jig_hole_mm = 0.03;
    o.jig_fixture_mm = 0.03;
    covers("cable_offset + pot_nonlinearity, plate holes 0.03 mm, fixture 0.03 mm",
           {"cable_offset", "pot_nonlinearity"}, o, 100);
}

} // namespace

int main() {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(exit_pulley_and_gains),
        cmocka_unit_test(anchors_on_a_noisy_jig),
        cmocka_unit_test(a_plate_with_hole_and_fixture_errors),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}

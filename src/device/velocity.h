// The holder's velocity for cdm_pose.velocity: the backward difference of
// successive positions over the device clock, through a first-order low-pass.
//
// Why this filter: a haptic loop wants a velocity now, not a smoother one
// later. The backward difference lags by half a report (0.5 ms at 1 kHz);
// the low-pass at 50 Hz (time constant 1/(2 pi 50) = 3.2 ms) takes the ADC
// quantisation's difference noise (about 4 mm/s rms at 1 kHz for 0.01 mm
// counts) down by a factor of about 2.7 and adds 3.2 ms of lag: about 3.7 ms
// in all, the same order as DHD's default velocity estimator window.
// Allocation-free; reader thread only.
#pragma once

#include <cmath>

namespace cdm {

class VelocityFilter {
public:
    static constexpr double kCutoffHz = 50.0;
    // A longer gap (a drop, a stall, a reconnection) restarts the estimate:
    // a difference across it would describe no real motion.
    static constexpr double kMaxGapS = 0.05;

    void reset() {
        have_ = false;
        v_[0] = v_[1] = v_[2] = 0;
    }

    // `fresh`: p is a newly computed position (not one held through an
    // out-of-workspace report). Writes mm/s into v_out.
    void update(const double p[3], double t_s, bool fresh, double v_out[3]) {
        if (!fresh) {
            reset();
        } else if (!have_) {
            remember(p, t_s);
            have_ = true;
        } else {
            const double dt = t_s - t_;
            if (!(dt > 0 && dt <= kMaxGapS)) {
                v_[0] = v_[1] = v_[2] = 0;
            } else {
                const double tau = 1.0 / (2.0 * 3.14159265358979323846 * kCutoffHz);
                const double a = dt / (tau + dt);
                for (int k = 0; k < 3; ++k) v_[k] += a * ((p[k] - p_[k]) / dt - v_[k]);
            }
            remember(p, t_s);
        }
        for (int k = 0; k < 3; ++k) v_out[k] = v_[k];
    }

private:
    void remember(const double p[3], double t_s) {
        for (int k = 0; k < 3; ++k) p_[k] = p[k];
        t_ = t_s;
    }

    bool have_ = false;
    double p_[3] = {0, 0, 0}, v_[3] = {0, 0, 0}, t_ = 0;
};

} // namespace cdm

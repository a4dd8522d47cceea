#include "device/sim/simulator.h"

#include <algorithm>
#include <cmath>

namespace cdm::sim {

using namespace cdm::proto;

Simulator::Simulator(ModelPtr truth, Firmware &fw, std::unique_ptr<Motion> motion, const SensorOptions &o)
    : model_(std::move(truth)), fw_(fw), motion_(std::move(motion)), o_(o), rng_(o.seed) {}

void Simulator::skip(uint64_t n) {
    index_ += n;
    overrun_ = n > 0;
}

bool Simulator::next(uint8_t *report, SimTruth &truth) {
    HandState s;
    const double t = double(index_) / o_.rate_hz;
    if (!motion_->at(index_, t, s)) return false;
    const DeviceInfoReport &info = fw_.info();

    InputReport r;
    r.sequence = uint32_t(index_);
    r.device_time_us = uint64_t(std::llround(double(index_) * 1e6 / o_.rate_hz));

    double readings[4];
    // A truth whose user effect cannot give readings here is a simulation
    // that cannot go on: the stream ends (never a NaN turned into counts).
    if (model_->readings(s.p, readings) != 0) return false;
    for (double v : readings)
        if (!std::isfinite(v)) return false;
    const double full_scale = double((1u << info.adc_bits) - 1);
    for (int i = 0; i < 4; ++i) {
        const double v = readings[i] + o_.noise_mm * normal_(rng_);
        // The firmware's ADC: the scale and offset it reports, as float32,
        // are exactly what the host will undo.
        const double counts = std::round((v - double(info.pot_offset_mm[i])) / double(info.pot_scale_mm[i]));
        r.pot_adc[i] = uint16_t(std::clamp(counts, 0.0, full_scale));
    }

    // IMU: the true orientation times a small random rotation.
    double dq[4] = {1, 0.5 * o_.imu_noise_rad * normal_(rng_), 0.5 * o_.imu_noise_rad * normal_(rng_),
                    0.5 * o_.imu_noise_rad * normal_(rng_)};
    double qm[4];
    quat_mul(s.q, dq, qm);
    const double qn = std::sqrt(qm[0] * qm[0] + qm[1] * qm[1] + qm[2] * qm[2] + qm[3] * qm[3]);
    for (int i = 0; i < 4; ++i)
        r.quat_q14[i] = int16_t(std::clamp(std::lround(qm[i] / qn * kQ14), -32768L, 32767L));

    // Hall: linear in the jaw angle between the two calibration points the
    // device info states, 12-bit ADC.
    const double frac = s.jaw_rad / double(info.grip_open_rad);
    const double hall = double(info.hall_closed) + frac * (double(info.hall_open) - double(info.hall_closed)) +
                        o_.hall_noise * normal_(rng_);
    r.hall_adc = uint16_t(std::clamp(std::round(hall), 0.0, 4095.0));
    r.buttons = s.buttons;
    r.status = kStatusImuOk | kStatusPotsOk | kStatusHallOk;
    if (fw_.calibration_stored()) r.status |= kStatusCalibrationStored;
    if (overrun_) r.status |= kStatusOverrun;
    overrun_ = false;
    serialize_input(r, report);

    truth.sequence = r.sequence;
    for (int i = 0; i < 3; ++i) truth.position[i] = s.p[i];
    for (int i = 0; i < 4; ++i) truth.orientation[i] = s.q[i];
    truth.grip = s.jaw_rad;
    truth.buttons = s.buttons;
    truth.jig_point = s.jig_point;
    ++index_;
    return true;
}

} // namespace cdm::sim

// The simulated master's sensors: turns the true hand state of a Motion into
// the input report the firmware would send, through a physical model of the
// device (cdm::Model: nominal geometry plus any hidden effects), Gaussian
// pot noise, 16-bit ADC quantisation, IMU noise and a Hall sensor.
#pragma once

#include <cstdint>
#include <memory>
#include <random>

#include "device/sim/firmware.h"
#include "device/sim/motion.h"
#include "device/sim/sim_truth.h"
#include "model/model.h"

namespace cdm::sim {

struct SensorOptions {
    double rate_hz = 1000.0;
    double noise_mm = 0.05;    // std of each pot reading (before quantisation)
    double imu_noise_rad = 0.001; // std of the IMU's small-angle error, per axis
    double hall_noise = 2.0;   // std of the Hall reading, counts
    uint64_t seed = 1;
};

class Simulator {
public:
    Simulator(ModelPtr truth, Firmware &fw, std::unique_ptr<Motion> motion, const SensorOptions &o);

    // Packs sample number index() into an input report (kInputReportSize
    // bytes) and advances. False, nothing written, when the motion is over.
    bool next(uint8_t *report, SimTruth &truth);
    // The firmware sampled n times but the host never read those reports
    // (its queue overflowed): the sequence jumps, and the next report says
    // so in its overrun status bit.
    void skip(uint64_t n);
    uint64_t index() const { return index_; }

private:
    ModelPtr model_;
    Firmware &fw_;
    std::unique_ptr<Motion> motion_;
    SensorOptions o_;
    std::mt19937_64 rng_;
    std::normal_distribution<double> normal_{0.0, 1.0};
    uint64_t index_ = 0;
    bool overrun_ = false;
};

} // namespace cdm::sim

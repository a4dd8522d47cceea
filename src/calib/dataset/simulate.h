// Jig datasets from a known model: the seed's experiment in software
// (hole plate, height fixture, repeated samples, pot noise and ADC
// quantisation, the jig's own errors). Used by the tests, by
// `cdm calib simulate`, and as the truth behind docs/calibration.md.
// The plan and the jig's error model are jig/'s, shared with the simulated
// master's motion=jig script; this writes the readings straight into a
// dataset instead of going through the HID protocol.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/dataset/dataset.h"
#include "jig/plan.h"
#include "model/model.h"

namespace cdm {

struct JigSimOptions {
    int n = 25;                 // holes per side
    double pitch_mm = 5.0;
    std::vector<double> heights{30, 40, 50, 60, 70};
    int samples = 100;
    double noise_mm = 0.05;     // per-sample pot noise (std)
    double quant_mm = 0.01;     // ADC step (mm per count)
    // The jig's errors (jig/errors.h): std of each visit's own seating
    // error per axis; of each hole's (y, z) error shared by every height;
    // of each fixture height's x error shared by every hole.
    double jig_tolerance_mm = 0.03;
    double jig_hole_mm = 0.0;
    double jig_fixture_mm = 0.0;
    uint64_t seed = 1;
    // Instead of the plate: as many positions drawn uniformly in the same
    // box (x over the heights' range), as a robot arm or tracker would give.
    bool scattered = false;
    // A planned session (`cdm calib plan`): only these positions of the
    // plate, in this order, each {x_ref, y_ref, z_ref, samples}; each must
    // be one of the plate's holes at one of the heights (within 1e-6 mm),
    // and keeps that position's point id and jig errors (the same plate as
    // the whole session's with the same seed). Empty: the whole plate.
    std::vector<std::array<double, 4>> plan;
};

// The options' jig and plan as the simulator would take them (the plate's
// fields; each plan position a hole at a height, whole samples): false +
// err naming the first that is not, before any file is opened.
bool check_jig_sim(const JigSimOptions &o, std::string &err);

// Streams the CSV through DatasetWriter (atomic; `protect_paths`, the
// caller's inputs, are refused as the target); false + err on I/O or model
// failure.
bool simulate_jig_csv(const Model &truth, const JigSimOptions &o, const std::string &path,
                      const std::vector<std::string> &protect_paths, std::string &err);
bool simulate_jig(const Model &truth, const JigSimOptions &o, Dataset &out, std::string &err);

} // namespace cdm

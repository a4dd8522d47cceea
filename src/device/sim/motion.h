// Scripted hand motions of the simulated master: where the holder truly is,
// how the grip is turned, the jaw and the buttons, at each sample.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <vector>

#include "jig/plan.h"
#include "jig/planned.h"
#include "model/model.h"

namespace cdm::sim {

struct HandState {
    double p[3] = {50, 0, 0};     // holder centre, device frame, mm
    double q[4] = {1, 0, 0, 0};   // grip orientation w,x,y,z
    double jaw_rad = 0;           // jaw opening
    uint16_t buttons = 0;         // cdm_button bits
    int jig_point = -1;           // jig plan position being dwelt on, else -1
};

class Motion {
public:
    virtual ~Motion() = default;
    // State at sample `index` (time t_s = index / rate). False when a scripted
    // motion is over (end of stream).
    virtual bool at(uint64_t index, double t_s, HandState &s) = 0;
};

// Smooth random hand motion within the workspace: y, z within +-60 mm, x
// within 30..70 mm (the seed's jig volume), orientation within +-0.6 rad per
// axis, the jaw opening and closing, now and then a clutch press.
std::unique_ptr<Motion> make_random_motion(uint64_t seed, double grip_open_rad);
// Holder at rest at (50, 0, 0), grip level, jaw closed.
std::unique_ptr<Motion> make_still_motion();
// A 40 mm circle in the y-z plane at x = 50 mm, one turn every 4 s.
std::unique_ptr<Motion> make_circle_motion(double grip_open_rad);

struct JigMotionOptions {
    JigPlanOptions plan;
    double tolerance_mm = 0.03; // std of each hole's error (y, z) and each height's fixture error (x)
    int transit = 20;           // samples spent moving between positions, MARK released
    uint64_t seed = 1;
    // A planned session (jig/planned.h, the URI's jig_plan): only these
    // positions of the plate, in this order, each with its samples. Empty:
    // every position of the plate, plan.samples each.
    std::vector<PlannedVisit> visits;
};
// The seed's calibration session: for each plan position in order (or
// each planned visit), a transit with MARK released, then its samples
// seated with MARK pressed. The true position is model.jig_to_device(reference + jig error);
// the jig errors come from the one jig error model (jig/errors.h): a hole is
// off by the same amount at every height, a fixture height by the same
// amount at every hole; tolerance_mm is the std of both.
std::unique_ptr<Motion> make_jig_motion(const ModelPtr &truth, const JigMotionOptions &o);

// Hamilton product r = a * b, quaternions w,x,y,z.
void quat_mul(const double a[4], const double b[4], double r[4]);
// Rotation by angles (rad) about x (roll), y (pitch), z (yaw), applied z-y-x.
void quat_from_rpy(double roll, double pitch, double yaw, double q[4]);

} // namespace cdm::sim

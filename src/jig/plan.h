// The jig plan: the ordered list of reference positions of a calibration
// session, as in the seed's experiment (a 25 x 25 hole plate at 5 mm pitch,
// a fixture at 30..70 mm, 100 samples at each position).
//
// Shared by the simulated master's `motion=jig` script (which moves the
// holder through the plan), by the dataset simulator (calib/simulate) and by
// `cdm record --jig` (which labels each MARK-pressed dwell with the next plan
// position): all walk the same list in the same order, so it is built in one
// place, below both simulators.
//
// Frame (project choice, the seed does not say): the jig's reference
// surface is the cable plane x = 0, so a fixture height h puts the holder
// centre at x = h in the jig frame; the plate is centred on y = z = 0 with
// its rows along y and columns along z. The jig frame equals the device
// frame unless the model says otherwise (Model::jig_to_device).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cdm {

struct JigPlanOptions {
    int n = 25;                                   // holes per side
    double pitch_mm = 5.0;                        // hole spacing
    std::vector<double> heights_mm{30, 40, 50, 60, 70};
    int samples = 100;                            // samples recorded at each position
};

struct JigPosition {
    int point = 0;        // running id, 0-based, the dataset's `point` column
    int height_index = 0; // index into heights_mm (-1: a scattered position)
    int row = 0;          // hole index along y, 0..n-1 (-1: not a hole)
    int col = 0;          // hole index along z, 0..n-1 (-1: not a hole)
    double ref[3] = {0, 0, 0}; // x (height), y, z in mm, jig frame
};

// Checks the options (n >= 1, pitch > 0, at least one height, every height
// > 0, samples >= 1); false + err naming the bad field.
bool check_jig_options(const JigPlanOptions &o, std::string &err);

// Heights outer, then rows (y), then columns (z): one fixture height is set
// up once and every hole is visited at it, as on the bench.
std::vector<JigPosition> make_jig_plan(const JigPlanOptions &o);

// As many positions as the plate plan has, drawn uniformly in the same box
// (x over the heights' range, y and z over the plate), as a robot arm or a
// tracker would give instead of a plate: no holes, no fixture heights.
std::vector<JigPosition> make_scattered_plan(const JigPlanOptions &o, uint64_t seed);

// "30,40,50" -> {30,40,50}; false + err on anything that is not a
// comma-separated list of positive numbers.
bool parse_heights(const std::string &text, std::vector<double> &out, std::string &err);

} // namespace cdm

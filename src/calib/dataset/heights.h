// A jig dataset's fixture heights (private to calib; read.cpp runs it once
// the file is read): which x_ref values are heights and which positions sit
// off their height (Dataset::heights, Dataset::off_height_points).
#pragma once

#include "calib/dataset/dataset.h"

namespace cdm {

// Sets d.heights and d.off_height_points from d.pos (the rule is
// Dataset::heights' comment in dataset.h).
void find_heights(Dataset &d);

} // namespace cdm

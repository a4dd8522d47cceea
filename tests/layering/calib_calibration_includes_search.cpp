// Not allowed: calib/calibration and calib/search are side by side, neither
// built on the other.
#include "calib/search/context.h"

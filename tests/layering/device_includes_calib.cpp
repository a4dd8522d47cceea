// Not allowed: device is not built on calib.
#include "calib/fit/fit.h"

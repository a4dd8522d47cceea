// Not allowed: calib/fit/problem.h is private to calib/fit.
#include "calib/fit/problem.h"

#include "calib/jig_plan.h"

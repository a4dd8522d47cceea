// Not allowed: calib/fit is below calib/diagnosis.
#include "calib/diagnosis/diagnose.h"

// Not allowed: calib/evaluation is below calib/search.
#include "calib/search/context.h"

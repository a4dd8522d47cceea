// Allowed: calib/search is built on calib/evaluation.
#include "calib/evaluation/eval.h"
int layering_probe_ok;

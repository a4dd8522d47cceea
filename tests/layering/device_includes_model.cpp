// Allowed: device is built on model.
#include "model/model.h"
int layering_probe_ok;

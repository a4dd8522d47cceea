// Not allowed: model is below device.
#include "device/device.h"

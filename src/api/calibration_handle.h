// The opaque cdm_calibration: an immutable model shared with devices.
#pragma once
#include "cdm/cdm.h"
#include "model/model.h"

struct cdm_calibration {
    cdm::ModelPtr model;
};

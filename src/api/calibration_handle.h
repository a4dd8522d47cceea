// The opaque cdm_calibration: an immutable model shared with devices.
#pragma once
#include "cdm/cdm.h"
#include <Eigen/Dense>

#include "model/model.h"

struct cdm_calibration {
    cdm::ModelPtr model;
    // The fitted parameters' covariance from the file's fit.covariance
    // (calib/evaluation/accuracy.h); empty when the file has none.
    Eigen::MatrixXd cov;
};

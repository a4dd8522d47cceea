// The steps cdm_diagnose and cdm_fit share: their options (one parser, errors
// with the option's column), their inputs (the dataset and the device
// description, told apart as unreadable or malformed, and checked to describe
// each other), the calibration they may write (its temporary created before
// the work, committed only after it succeeded) and the JSON they hand back.
#pragma once
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/dataset/dataset.h"
#include "io/file.h"
#include "model/model.h"

namespace cdm::api {

struct JobArgs {
    std::vector<std::string> effects;
    double jig_tolerance_mm = -1; // < 0: estimated from the data
    double max_error_mm = -1;     // a check's: < 0, none
    bool candidates = true, search = true, validation = true, per_position = true, outliers = true; // DiagnoseOptions defaults
    std::string calib_out;
};

// Which job's options: each refuses the others' own.
enum class JobKind { Fit, Diagnosis, Check };

// Parses `text` (NULL or empty: defaults). Diagnosis: its own options
// (candidates, search, validation, per_position) are accepted. Fit:
// requires a non-empty "effects". Both take "outliers" and
// "calibration_out". Check: "jig_tolerance_mm" and "max_error_mm" only.
int parse_job_options(const char *text, const char *fn, JobKind kind, JobArgs &out);

struct JobInputs {
    Dataset data;
    DeviceGeometry geometry;
    io::AtomicFile calib_out; // open when the options asked for a calibration
};

// Opens the output first (a special file or one of the inputs is refused
// before any work), then reads the dataset and the device description and
// checks that most positions can be placed by the nominal triangulation.
int open_job(const char *data_path, const char *device_path, const JobArgs &a, JobInputs &in);
// The dataset alone, checked against a geometry already at hand (a
// calibration's): open_job without the output or the device file.
int open_job_data(const char *data_path, const DeviceGeometry &g, JobInputs &in);

// Writes the fitted model as a calibration, if one was asked for. Its
// "fit" block says where it came from: the data file, the fitted model's
// error, and what of the data the fit did not use (`outliers`, `glitches`:
// the job's blocks, calib/calibration/fit_outliers.h and glitches_json), so a reader of
// the calibration alone knows which positions and samples were left out.
// `covariance`: the fitted parameters' (calib/evaluation/accuracy.h's
// covariance_json), kept in the "fit" block for
// cdm_calibration_position_covariance.
int commit_calibration(JobInputs &in, const Model &fitted, const char *data_path, const nlohmann::json &error_mm,
                       const nlohmann::json &outliers, const nlohmann::json &glitches,
                       const nlohmann::json &covariance);

// A malloc'ed copy of j.dump() into *out (freed with cdm_free_string).
int return_json(const nlohmann::json &j, const char *fn, char **out);

} // namespace cdm::api

list(APPEND CDM_SOURCES
  calib/jig_plan.cpp
  calib/dataset.cpp
  calib/fit.cpp
  calib/simulate.cpp
  calib/diagnose.cpp
  calib/diag_stats.cpp
  calib/diag_eval.cpp
  calib/diag_spatial.cpp
  calib/diag_residual.cpp
  calib/fit_calibration.cpp
  calib/diag_findings.cpp)

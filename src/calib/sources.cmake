list(APPEND CDM_SOURCES
  calib/jig_plan.cpp
  calib/dataset.cpp
  calib/fit.cpp
  calib/fit_ellipsoid.cpp
  calib/simulate.cpp
  calib/diagnose.cpp)

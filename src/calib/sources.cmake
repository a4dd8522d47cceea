list(APPEND CDM_SOURCES
  calib/dataset.cpp
  calib/fit.cpp
  calib/simulate.cpp
  calib/diagnose.cpp)

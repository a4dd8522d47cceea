list(APPEND CDM_SOURCES
  calib/jig_plan.cpp)

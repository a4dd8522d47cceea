list(APPEND CDM_SOURCES
  api/version_error.cpp)
list(APPEND CDM_SOURCES
  api/device_api.cpp)
list(APPEND CDM_SOURCES
  api/calibration_api.cpp)
list(APPEND CDM_SOURCES
  api/cli_support_api.cpp)

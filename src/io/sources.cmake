list(APPEND CDM_SOURCES
  io/file.cpp
  io/json.cpp
  io/device_json.cpp
  io/calibration_json.cpp)

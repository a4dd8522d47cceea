list(APPEND CDM_SOURCES
  api/version_error.cpp)

list(APPEND CDM_SOURCES
  model/geometry.cpp
  model/model.cpp)

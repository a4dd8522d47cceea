list(APPEND CDM_SOURCES
  model/geometry.cpp
  model/model.cpp
  model/model_position.cpp
  model/layout.cpp
  model/evaluator.cpp
  model/registry.cpp
  model/catalogue.cpp
  model/model_json.cpp)

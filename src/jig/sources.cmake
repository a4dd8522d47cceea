# The jig: the hole plan and the jig's error model, below both simulators.
list(APPEND CDM_SOURCES
  jig/plan.cpp
  jig/errors.cpp)

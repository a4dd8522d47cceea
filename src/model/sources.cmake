list(APPEND CDM_SOURCES
  model/geometry.cpp
  model/model.cpp
  model/effects/registry.cpp
  model/effects/jig_misalignment.cpp
  model/effects/anchor_position.cpp
  model/effects/holder_geometry.cpp
  model/effects/cable_offset.cpp
  model/effects/cable_gain.cpp
  model/effects/pot_nonlinearity.cpp
  model/effects/exit_pulley.cpp
  model/effects/cable_stretch.cpp
  model/effects/ellipsoid.cpp)

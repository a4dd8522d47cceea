# Owned by the device layer: protocol, transports, reader thread.
list(APPEND CDM_SOURCES
  device/protocol.cpp
  device/transport_registry.cpp
  device/transport_hidapi.cpp
  device/hidraw_check.cpp
  device/transport_sim.cpp
  device/transport_replay.cpp
  device/replay_format.cpp
  device/device.cpp
  device/device_calibration.cpp
  device/sim/firmware.cpp
  device/sim/motion.cpp
  device/sim/simulator.cpp
  device/sim/faults.cpp)

# Owned by the device layer: protocol, transports, reader thread.
list(APPEND CDM_SOURCES)

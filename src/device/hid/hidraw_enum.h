// The masters' hidraw nodes, enumerated through libudev with every value
// checked, in place of hidapi's hid_enumerate(): Debian's hidapi 0.13.1
// passed a NULL attribute of a half-made or half-gone node to strlen (a
// SIGSEGV in the caller's process, about once in 100-200 re-plugs of the
// emulated master; docs/reliability.md). Enumeration runs exactly then: on
// the watcher's thread right after a udev event, and on a reader thread
// reconnecting by serial. A node missing any of its parts is not listed
// (the watcher enumerates again at the node's next udev event; a
// reconnection, at its next attempt).
#pragma once

#include <cstddef>

extern "C" {
// Called once per master node (VID/PID of protocol.h on the USB bus,
// subsystem hidraw):
// its devnode ("/dev/hidrawN"), the HID device's unique id (the USB serial
// string; "" if none) and the USB device's bcdDevice (0 if unknown). The
// strings live until the callback returns.
typedef void (*cdm_hidraw_master_fn)(void *ctx, const char *devnode, const char *serial, unsigned release);

// 0 after calling `fn` for every master found (none is not an error);
// otherwise a CDM_ERR_* code and a NUL-terminated reason in why[0..cap),
// and `fn` may still have been called for the masters that were listed (a
// scan that met a changing device): the list may be incomplete.
// C linkage so that the hidapi mock test can wrap it
// (-Wl,--wrap=cdm_hidraw_list_masters): its fake master has no sysfs.
int cdm_hidraw_list_masters(cdm_hidraw_master_fn fn, void *ctx, char *why, size_t cap);
}

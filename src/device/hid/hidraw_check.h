// Checks that a path names a hidraw character device before hidapi sees it:
// hidapi-hidraw (0.13.1) crashes on /dev/null, /dev/zero or a regular file,
// and a FIFO without a writer would block its open forever.
#pragma once

#include <cstddef>

extern "C" {
// 0 when `path` is a character device that sysfs calls hidraw, opens
// (non-blocking) for reading and writing, and answers HIDIOCGRDESCSIZE.
// Otherwise a CDM_ERR_* code and a NUL-terminated reason in why[0..cap)
// naming the path. C linkage so that the hidapi mock test can wrap it
// (-Wl,--wrap=cdm_hidraw_node_check): its fake /dev/hidraw7 does not exist.
int cdm_hidraw_node_check(const char *path, char *why, size_t cap);
}

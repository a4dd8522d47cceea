#include "device/hid/hidraw_check.h"

#include <fcntl.h>
#include <linux/hidraw.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "cdm/cdm.h"
#include "io/file.h"

namespace {

int fail(char *why, size_t cap, int code, const std::string &text) {
    if (why && cap) std::snprintf(why, cap, "%s", text.c_str());
    return code;
}

// The subsystem a character device belongs to, from sysfs ("" if unknown).
std::string char_subsystem(dev_t rdev, std::string &detail) {
    const std::string link = "/sys/dev/char/" + std::to_string(major(rdev)) + ":" + std::to_string(minor(rdev)) +
                             "/subsystem";
    char target[512];
    const ssize_t n = ::readlink(link.c_str(), target, sizeof target - 1);
    if (n < 0) {
        detail = link + ": " + std::strerror(errno);
        return "";
    }
    target[n] = 0;
    const char *slash = std::strrchr(target, '/');
    return slash ? slash + 1 : target;
}

} // namespace

extern "C" int cdm_hidraw_node_check(const char *path, char *why, size_t cap) {
    const std::string p = path ? path : "";
    struct stat st;
    if (::stat(p.c_str(), &st) != 0)
        return fail(why, cap, CDM_ERR_NO_DEVICE, p + ": " + std::strerror(errno));
    if (!S_ISCHR(st.st_mode))
        return fail(why, cap, CDM_ERR_NO_DEVICE, p + " is " + cdm::io::file_kind(st.st_mode) + ", not a hidraw device");
    std::string detail;
    const std::string sub = char_subsystem(st.st_rdev, detail);
    if (sub != "hidraw")
        return fail(why, cap, CDM_ERR_NO_DEVICE,
                    p + " is a character device of subsystem \"" + (sub.empty() ? "unknown" : sub) +
                        "\", not a hidraw device" + (detail.empty() ? "" : " (" + detail + ")"));
    // O_NONBLOCK: the probe must never hang, whatever the node turns out to be.
    const int fd = ::open(p.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0)
        return fail(why, cap, CDM_ERR_NO_DEVICE,
                    p + ": cannot open: " + std::strerror(errno) +
                        (errno == EACCES ? " (see udev/70-cdm.rules for access without root)" : ""));
    int size = 0;
    const int rc = ::ioctl(fd, HIDIOCGRDESCSIZE, &size);
    const int e = errno;
    ::close(fd);
    if (rc < 0)
        return fail(why, cap, CDM_ERR_NO_DEVICE, p + ": does not answer HIDIOCGRDESCSIZE: " + std::strerror(e));
    // The kernel caps report descriptors at HID_MAX_DESCRIPTOR_SIZE (4096):
    // anything else is a node that only pretends to be hidraw.
    if (size <= 0 || size > HID_MAX_DESCRIPTOR_SIZE)
        return fail(why, cap, CDM_ERR_NO_DEVICE,
                    p + ": HIDIOCGRDESCSIZE answered " + std::to_string(size) + ", not a report descriptor size 1..4096");
    return CDM_OK;
}

// extern "C" device functions: argument checks, struct_size handling and
// exception fences around the device layer (src/device/). No logic of their
// own.
#include <algorithm>
#include <cstddef>
#include <cstring>
#include <new>
#include <string>
#include <vector>

#include "api/calibration_handle.h"
#include "api/errors.h"
#include "cdm/cdm.h"
#include "device/device.h"
#include "device/hid/transport_hidapi.h"

// The 1.0 sizes are part of the ABI: a caller passing less is refused, a
// newer caller passing more gets the 1.0 fields and the rest untouched.
static_assert(offsetof(cdm_pose, host_sequence) == 104, "cdm_pose 1.0 is 104 bytes");
static_assert(offsetof(cdm_pose, velocity) == 112 && sizeof(cdm_pose) == 136, "cdm_pose 1.1 is 136 bytes");
static_assert(sizeof(cdm_raw) == 80, "cdm_raw 1.0 is 80 bytes");
static_assert(sizeof(cdm_device_info) == 456, "cdm_device_info 1.0 is 456 bytes");
static_assert(offsetof(cdm_stats, sequence_jumps) == 48, "cdm_stats 1.0 is 48 bytes");
static_assert(offsetof(cdm_stats, restarts) == 72 && sizeof(cdm_stats) == 80, "cdm_stats 1.1 is 72 bytes, 1.2 80");
static_assert(offsetof(cdm_open_options, on_event) == 24 && offsetof(cdm_open_options, on_rejected) == 32 &&
                  sizeof(cdm_open_options) == 40,
              "cdm_open_options 1.0 is 24 bytes, 1.1 is 32, 1.2 40");
static_assert(sizeof(cdm_rejected) == 40, "cdm_rejected 1.2 is 40 bytes");
static_assert(sizeof(cdm_sample) == 40, "cdm_sample 1.1 is 40 bytes (1.0: 32)");

struct cdm_device_list {
    std::vector<cdm_device_info> items;
};

namespace {

constexpr uint32_t kPoseSize11 = 112;
constexpr uint32_t kPoseSize10 = 104, kRawSize10 = 80, kInfoSize10 = 456, kStatsSize10 = 48,
                   kOptionsSize10 = 24;

// Writes the fields of `src` that fit in the caller's struct_size. Does not
// allocate (cdm_get_pose relies on it). The current size, the common case,
// is a copy of constant length that the compiler inlines; a variable length
// becomes `rep movs`, whose start-up alone cost cdm_get_pose several ns.
template <class T>
void copy_out(const T &src, T *dst) {
    const uint32_t cs = dst->struct_size;
    if (cs >= sizeof(T))
        std::memcpy(static_cast<void *>(dst), &src, sizeof(T));
    else
        std::memcpy(static_cast<void *>(dst), &src, cs);
    dst->struct_size = cs;
}

int bad_size(const char *fn, const char *type, uint32_t got, uint32_t need) {
    return cdm::fail(CDM_ERR_INVALID_ARG, std::string(fn) + ": " + type + ".struct_size is " + std::to_string(got) +
                                              ", at least " + std::to_string(need) + " needed");
}

} // namespace

extern "C" {

int cdm_enumerate(cdm_device_list **out) {
    return cdm::guarded("cdm_enumerate", [&] {
        if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_enumerate: out is NULL");
        *out = nullptr;
        auto list = std::make_unique<cdm_device_list>();
        std::string err;
        cdm::hid_list_masters(list->items, err);
        if (!err.empty()) cdm::fail(CDM_OK, err); // informative: why the list may be empty
        *out = list.release();
        return int(CDM_OK);
    });
}

size_t cdm_device_list_count(const cdm_device_list *list) { return list ? list->items.size() : 0; }

int cdm_device_list_get(const cdm_device_list *list, size_t i, cdm_device_info *info) {
    return cdm::guarded("cdm_device_list_get", [&] {
        if (!list || !info) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_device_list_get: NULL argument");
        if (info->struct_size < kInfoSize10)
            return bad_size("cdm_device_list_get", "cdm_device_info", info->struct_size, kInfoSize10);
        if (i >= list->items.size())
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_device_list_get: index " + std::to_string(i) +
                                                      " of a list of " + std::to_string(list->items.size()));
        copy_out(list->items[i], info);
        return int(CDM_OK);
    });
}

void cdm_device_list_free(cdm_device_list *list) { delete list; }

int cdm_open_ex(const char *uri, const cdm_open_options *options, cdm_device **out) {
    return cdm::guarded("cdm_open_ex", [&] {
        if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_open: out is NULL");
        *out = nullptr;
        cdm_open_options opts{};
        if (options) {
            if (options->struct_size < kOptionsSize10)
                return bad_size("cdm_open_ex", "cdm_open_options", options->struct_size, kOptionsSize10);
            // The fields of the newest size the caller's struct_size covers
            // whole (24, 32, 40: never part of a pointer); the rest stay zero.
            const size_t n = options->struct_size >= sizeof opts                          ? sizeof opts
                             : options->struct_size >= offsetof(cdm_open_options, on_rejected) ? offsetof(cdm_open_options, on_rejected)
                                                                                                : size_t(kOptionsSize10);
            std::memcpy(&opts, options, n);
            opts.struct_size = sizeof opts;
        }
        std::string err;
        const int rc = cdm::open_device(uri, options ? &opts : nullptr, out, err);
        if (rc != CDM_OK) return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_open(const char *uri, cdm_device **out) { return cdm_open_ex(uri, nullptr, out); }

void cdm_close(cdm_device *dev) {
    if (!dev) return;
    try {
        if (dev->on_reader_thread()) {
            // From a callback (or the log sink) on the device's own reader
            // thread: joining it would be a self-join. The reader frees the
            // handle once the callback returns. No log message: a sink that
            // closes on every message would be called again from here.
            dev->close_from_callback();
            cdm::fail_static(CDM_OK, "cdm_close: deferred: called on the device's own reader thread (a callback "
                                     "or the log sink); the handle is freed when the callback returns");
            return;
        }
        delete dev;
    } catch (...) {
        // A destructor that throws has nowhere to report to: swallow, the
        // handle is gone either way.
    }
}

int cdm_shutdown(cdm_device *dev) {
    if (!dev) return cdm::fail_static(CDM_ERR_INVALID_ARG, "cdm_shutdown: dev is NULL");
    cdm::clear_thread_error_rt();
    dev->shutdown();
    return CDM_OK;
}

// No allocation, no lock: this is the 1 kHz call. The thread error is
// emptied on entry and, on any return but CDM_OK, set to a constant text
// (fail_static: nothing allocated or freed), so that cdm_thread_error after
// a failing call says why, never what an earlier call said.
namespace {
struct PoseTexts {
    const char *null_arg, *small, *no_report, *no_position, *stale, *disconnected, *end, *timeout, *own_thread,
        *closed;
};
#define CDM_POSE_TEXTS(fn)                                                                                          \
    PoseTexts {                                                                                                      \
        fn ": NULL device or output", fn ": struct_size is below the oldest size this call accepts",                \
            fn ": no report received yet",                                                                           \
            fn ": no position yet: every report so far was out of the workspace (flags NO_POSITION, "               \
               "OUT_OF_WORKSPACE)",                                                                                  \
            fn ": the newest pose is older than the stale deadline (flag STALE)",                                   \
            fn ": the device is disconnected; the last pose, if any, is held (cdm_device_error says why)",          \
            fn ": the stream has ended (flag END_OF_STREAM)", fn ": no newer pose within the timeout",              \
            fn ": called on the device's own reader thread (from its callback), where no pose can arrive while "    \
               "it waits; use cdm_get_pose there",                                                                   \
            fn ": the handle was closed (cdm_close or cdm_shutdown): no pose"                                        \
    }
constexpr PoseTexts kGetPose = CDM_POSE_TEXTS("cdm_get_pose");
constexpr PoseTexts kGetRaw = CDM_POSE_TEXTS("cdm_get_raw");
constexpr PoseTexts kWaitPose = CDM_POSE_TEXTS("cdm_wait_pose");
constexpr PoseTexts kWaitPoseAfter = CDM_POSE_TEXTS("cdm_wait_pose_after");
#undef CDM_POSE_TEXTS

int pose_status(int rc, uint32_t flags, const PoseTexts &t) noexcept {
    switch (rc) {
    case CDM_OK: return rc;
    case CDM_ERR_NO_DATA: return cdm::fail_static(rc, (flags & CDM_POSE_NO_POSITION) ? t.no_position : t.no_report);
    case CDM_ERR_STALE: return cdm::fail_static(rc, t.stale);
    case CDM_ERR_DISCONNECTED: return cdm::fail_static(rc, t.disconnected);
    case CDM_ERR_END_OF_STREAM: return cdm::fail_static(rc, t.end);
    case CDM_ERR_TIMEOUT: return cdm::fail_static(rc, t.timeout);
    case CDM_ERR_INVALID_ARG: return cdm::fail_static(rc, t.own_thread);
    case CDM_ERR_CLOSED: return cdm::fail_static(rc, t.closed);
    default: return rc;
    }
}
} // namespace
int cdm_get_pose(cdm_device *dev, cdm_pose *out) {
    cdm::clear_thread_error_rt();
    if (!dev || !out) return cdm::fail_static(CDM_ERR_INVALID_ARG, kGetPose.null_arg);
    if (out->struct_size < kPoseSize10) return cdm::fail_static(CDM_ERR_INVALID_ARG, kGetPose.small);
    const uint32_t cs = out->struct_size;
    if (cs >= sizeof(cdm_pose)) {
        // The current size: straight from the sequence lock into the
        // caller's struct, no intermediate copy.
        const int rc = dev->get_pose(*out);
        out->struct_size = cs;
        return rc == CDM_OK ? rc : pose_status(rc, out->flags, kGetPose);
    }
    cdm_pose p;
    const int rc = dev->get_pose(p);
    copy_out(p, out);
    return rc == CDM_OK ? rc : pose_status(rc, p.flags, kGetPose);
}

int cdm_wait_pose(cdm_device *dev, int timeout_ms, cdm_pose *out) {
    return cdm::guarded("cdm_wait_pose", [&] {
        if (!dev || !out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_wait_pose: NULL argument");
        if (out->struct_size < kPoseSize10) return bad_size("cdm_wait_pose", "cdm_pose", out->struct_size, kPoseSize10);
        cdm_pose p;
        const int rc = dev->wait_pose(timeout_ms, p);
        copy_out(p, out);
        return pose_status(rc, p.flags, kWaitPose);
    });
}

int cdm_wait_pose_after(cdm_device *dev, uint64_t after_host_sequence, int timeout_ms, cdm_pose *out) {
    return cdm::guarded("cdm_wait_pose_after", [&] {
        if (!dev || !out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_wait_pose_after: NULL argument");
        // The caller must be able to see host_sequence, or it cannot ask again.
        if (out->struct_size < kPoseSize11)
            return bad_size("cdm_wait_pose_after", "cdm_pose", out->struct_size, kPoseSize11);
        cdm_pose p;
        const int rc = dev->wait_pose_after(after_host_sequence, timeout_ms, p);
        copy_out(p, out);
        return pose_status(rc, p.flags, kWaitPoseAfter);
    });
}

int cdm_get_raw(cdm_device *dev, cdm_raw *out) {
    cdm::clear_thread_error_rt();
    if (!dev || !out) return cdm::fail_static(CDM_ERR_INVALID_ARG, kGetRaw.null_arg);
    if (out->struct_size < kRawSize10) return cdm::fail_static(CDM_ERR_INVALID_ARG, kGetRaw.small);
    cdm_raw r;
    const int rc = dev->get_raw(r);
    copy_out(r, out);
    // cdm_raw has no flags: a report received (host time set) with no
    // pose is one that could not be solved.
    return rc == CDM_OK ? rc : pose_status(rc, r.host_time_ns != 0 ? uint32_t(CDM_POSE_NO_POSITION) : 0u, kGetRaw);
}

int cdm_get_info(cdm_device *dev, cdm_device_info *out) {
    return cdm::guarded("cdm_get_info", [&] {
        if (!dev || !out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_get_info: NULL argument");
        if (out->struct_size < kInfoSize10)
            return bad_size("cdm_get_info", "cdm_device_info", out->struct_size, kInfoSize10);
        cdm_device_info i;
        dev->get_info(i);
        copy_out(i, out);
        return int(CDM_OK);
    });
}

int cdm_set_stale_timeout(cdm_device *dev, uint32_t timeout_us) {
    return cdm::guarded("cdm_set_stale_timeout", [&] {
        if (!dev) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_set_stale_timeout: dev is NULL");
        dev->set_stale_timeout(timeout_us);
        return int(CDM_OK);
    });
}

int cdm_get_stats(cdm_device *dev, cdm_stats *out) {
    return cdm::guarded("cdm_get_stats", [&] {
        if (!dev || !out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_get_stats: NULL argument");
        if (out->struct_size < kStatsSize10)
            return bad_size("cdm_get_stats", "cdm_stats", out->struct_size, kStatsSize10);
        cdm_stats s;
        dev->get_stats(s);
        copy_out(s, out);
        return int(CDM_OK);
    });
}

// Not through cdm::guarded: reading the device's text leaves this thread's
// text (a failing call's, read before or after it) alone. Nothing in it
// allocates: a copy into the caller's buffer under the device's error mutex.
int cdm_device_error(cdm_device *dev, char *buf, size_t len) {
    if (!dev || !buf || len == 0)
        return cdm::fail_noexcept(CDM_ERR_INVALID_ARG, "cdm_device_error", "NULL or empty buffer");
    dev->error_text(buf, len);
    return CDM_OK;
}

int cdm_set_calibration(cdm_device *dev, const cdm_calibration *cal) {
    return cdm::guarded("cdm_set_calibration", [&] {
        if (!dev) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_set_calibration: dev is NULL");
        if (cal && !cal->model) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_set_calibration: empty calibration");
        if (cal) {
            const std::string why = dev->geometry_mismatch(*cal->model);
            if (!why.empty()) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_set_calibration: " + why);
        }
        // The model is immutable and shared: the device keeps its own
        // reference, so the caller may free cal right away.
        dev->set_model(cal ? cal->model : cdm::ModelPtr());
        return int(CDM_OK);
    });
}

int cdm_device_calibration_read(cdm_device *dev, char *buf, size_t cap, size_t *len) {
    return cdm::guarded("cdm_device_calibration_read", [&] {
        if (!dev || !len || (!buf && cap > 0))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_device_calibration_read: NULL argument");
        const int rc = dev->calibration_read(buf, cap, len);
        if (rc != CDM_OK) {
            char text[512];
            dev->error_text(text, sizeof text);
            return cdm::fail(rc, text);
        }
        return rc;
    });
}

int cdm_device_calibration_write(cdm_device *dev, const char *data, size_t len) {
    return cdm::guarded("cdm_device_calibration_write", [&] {
        if (!dev || (!data && len > 0))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_device_calibration_write: NULL argument");
        const int rc = dev->calibration_write(data, len);
        if (rc != CDM_OK) {
            char text[512];
            dev->error_text(text, sizeof text);
            return cdm::fail(rc, text);
        }
        return rc;
    });
}

} // extern "C"

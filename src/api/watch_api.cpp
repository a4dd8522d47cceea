// extern "C" hot-plug functions (cdm_watch): argument checks and the
// exception fence around device/hotplug.h. No logic of their own.
#include <cstddef>
#include <cstdio>
#include <memory>
#include <string>

#include "api/errors.h"
#include "cdm/cdm.h"
#include "device/device.h"
#include "device/hotplug.h"
#include "io/log.h"

static_assert(sizeof(cdm_watch_event) == 24 && offsetof(cdm_watch_event, info) == 16,
              "cdm_watch_event (experimental 1) is 24 bytes");

struct cdm_watcher {
    std::unique_ptr<cdm::MasterWatcher> impl;
};

extern "C" {

int cdm_watch(uint32_t flags, cdm_watch_fn fn, void *user, cdm_watcher **out) {
    return cdm::guarded("cdm_watch", [&] {
        if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_watch: out is NULL");
        *out = nullptr;
        if (!fn) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_watch: fn is NULL");
        if (flags & ~uint32_t(CDM_WATCH_ENUMERATE))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_watch: unknown flags 0x" + [&] {
                char b[16];
                std::snprintf(b, sizeof b, "%x", unsigned(flags & ~uint32_t(CDM_WATCH_ENUMERATE)));
                return std::string(b);
            }());
        auto w = std::make_unique<cdm_watcher>();
        std::string err;
        const int rc = cdm::MasterWatcher::start(
            (flags & CDM_WATCH_ENUMERATE) != 0,
            [fn, user](uint32_t kind, const cdm_device_info &info) {
                cdm_watch_event e{};
                e.struct_size = sizeof e;
                e.kind = kind;
                e.host_time_ns = cdm::monotonic_ns();
                e.info = &info;
                fn(user, &e);
            },
            w->impl, err);
        if (rc != CDM_OK) return cdm::fail(rc, "cdm_watch: " + err);
        *out = w.release();
        return int(CDM_OK);
    });
}

void cdm_watch_free(cdm_watcher *watcher) {
    if (!watcher) return;
    if (watcher->impl && watcher->impl->on_own_thread()) {
        cdm::log::message(cdm::log::kError,
                          "cdm_watch_free called from the watcher's own callback: refused (it would join its own "
                          "thread); the watcher keeps running");
        return;
    }
    delete watcher; // joins the watcher's thread
}

} // extern "C"

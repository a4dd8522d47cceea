// `hid:` — the real master through hidapi's hidraw backend.
//
// Concurrency: the reader thread is the only caller of hid_read_timeout and
// the only one that closes or reopens the hid_device; feature reports may
// come from any thread. mu_ guards the handle pointer against a reopen under
// a feature transfer; the reader does not take it to read, since nobody else
// ever changes the pointer.
#include <hidapi.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cwchar>
#include <memory>
#include <mutex>
#include <set>

#include "cdm/cdm.h"
#include "device/device.h"
#include "device/hid/hidraw_check.h"
#include "device/hid/hidraw_enum.h"
#include "device/hotplug.h"
#include "device/protocol.h"
#include "device/transport.h"
#include "device/hid/transport_hidapi.h"

namespace cdm {

namespace {

std::once_flag g_hid_init_once;
int g_hid_init_rc = 0;

int ensure_hid_init(std::string &err) {
    // hid_init is not thread-safe and must run once per process; hid_exit is
    // never called, other code in the process may use hidapi too.
    std::call_once(g_hid_init_once, [] { g_hid_init_rc = hid_init(); });
    if (g_hid_init_rc != 0) {
        err = "hid_init failed";
        return CDM_ERR_IO;
    }
    return CDM_OK;
}

std::string narrow(const wchar_t *w) {
    std::string s;
    for (; w && *w; ++w) s += (*w >= 0x20 && *w < 0x7F) ? char(*w) : '?';
    return s;
}

std::string hid_err(hid_device *d) {
    const wchar_t *w = hid_error(d);
    return w ? narrow(w) : std::string("unknown hidapi error");
}

// The bytes of a udev property as the CLI and the C API show them: printable
// ASCII kept, anything else '?', as narrow() does to hidapi's wide strings.
std::string printable(const char *s) {
    std::string out;
    for (; s && *s; ++s) out += (*s >= 0x20 && *s < 0x7F) ? *s : '?';
    return out;
}

// Every connected master's node, each once, through libudev
// (device/hid/hidraw_enum.h: hidapi's own enumeration crashed on a node being
// made or removed, which is exactly when a watcher or a reconnection by
// serial enumerates). err says why the list may be incomplete (a scan that
// met a changing device), or why nothing could be listed.
std::vector<MasterNode> master_nodes(std::string &err) {
    std::vector<MasterNode> out;
    std::set<std::string> seen;
    struct Ctx {
        std::vector<MasterNode> *out;
        std::set<std::string> *seen;
    } ctx{&out, &seen};
    char why[256] = "";
    const int rc = cdm_hidraw_list_masters(
        [](void *c, const char *node, const char *serial, unsigned release) {
            Ctx &x = *static_cast<Ctx *>(c);
            if (!node || !x.seen->insert(node).second) return; // one entry per node
            MasterNode n;
            n.path = node;
            n.serial = printable(serial);
            n.release = uint16_t(release);
            x.out->push_back(std::move(n));
        },
        &ctx, why, sizeof why);
    if (rc != 0) err = why;
    return out;
}

// The master node `path` names, as the enumeration knows it (its own
// /dev/hidrawN and its serial): the node itself, or another name for it (a
// udev rule's SYMLINK+="cdm-master", a hard link): the same inode, or the
// same character device number. False when no enumerated master is there
// (the handle then reconnects by the path it was given). Not hidapi's
// hid_get_serial_number_string: in 0.13.1 it goes through the same
// unchecked sysfs reads that crashed hid_enumerate on a node being made or
// removed (docs/reliability.md), and an open right after an arrival is
// exactly then. The same source as find_by_serial, so a reconnection
// compares like with like. (stat, not realpath: under umockdev's preload,
// which wraps realpath, it smashed the stack.)
bool master_named_by(const std::string &path, MasterNode &out) {
    std::string err;
    const std::vector<MasterNode> nodes = master_nodes(err);
    for (const MasterNode &n : nodes)
        if (n.path == path) {
            out = n;
            return true;
        }
    struct stat a {};
    if (::stat(path.c_str(), &a) != 0) return false;
    for (const MasterNode &n : nodes) {
        struct stat b {};
        if (::stat(n.path.c_str(), &b) != 0) continue;
        const bool same_inode = a.st_dev == b.st_dev && a.st_ino == b.st_ino;
        const bool same_device = S_ISCHR(a.st_mode) && S_ISCHR(b.st_mode) && a.st_rdev == b.st_rdev;
        if (same_inode || same_device) {
            out = n;
            return true;
        }
    }
    return false;
}

// Path of the connected master with this serial number, or "".
std::string find_by_serial(const std::string &serial) {
    std::string err;
    for (const MasterNode &n : master_nodes(err))
        if (n.serial == serial) return n.path;
    return "";
}

// hidapi is handed only a node that passed cdm_hidraw_node_check.
int checked_open(const std::string &path, hid_device *&d, std::string &why) {
    char buf[512];
    const int rc = cdm_hidraw_node_check(path.c_str(), buf, sizeof buf);
    if (rc != CDM_OK) {
        why = buf;
        return rc;
    }
    {
        // hid_open_path re-runs hid_init, which frees and resets hidapi's
        // process-wide error text (0.13.1): opens, and the read of that
        // text after a failed one, are serialised, or one thread's open
        // frees the text another is reading. Opens are rare (open,
        // reconnection, the watcher's info read).
        static std::mutex open_mu;
        std::lock_guard<std::mutex> lock(open_mu);
        d = hid_open_path(path.c_str());
        if (!d) why = "cannot open " + path + ": " + hid_err(nullptr);
    }
    if (!d) return CDM_ERR_NO_DEVICE;
    return CDM_OK;
}

class HidTransport final : public Transport {
public:
    HidTransport(hid_device *dev, std::string path, std::string serial)
        : dev_(dev), path_(std::move(path)), serial_(std::move(serial)) {}
    ~HidTransport() override {
        if (dev_) hid_close(dev_);
    }

    int read(uint8_t *buf, size_t cap, int timeout_ms, std::string &err) override {
        if (!dev_) return kReadDisconnected;
        const int n = hid_read_timeout(dev_, buf, cap, timeout_ms);
        if (n >= 0) return n; // 0: timeout
        // hidraw: -1 means the node went away (unplug) or a read error; both
        // leave the handle useless, so close it and let the reader reopen.
        err = "hid_read_timeout: " + hid_err(dev_);
        {
            std::lock_guard<std::mutex> lock(mu_);
            hid_close(dev_);
            dev_ = nullptr;
        }
        // Subscribed now, before the reader's first reopen attempt: an
        // arrival after that attempt is queued in the socket, not missed.
        if (hotplug_events() && !mon_) mon_ = std::make_unique<UdevMonitor>();
        return kReadDisconnected;
    }

    bool wait_arrival(int timeout_ms) override {
        if (!mon_ || !mon_->ok()) return Transport::wait_arrival(timeout_ms);
        // Any hidraw or USB device "add": the master's hidraw "add" comes
        // last, but a reopen costs only one enumeration and so nothing
        // depends on the order (docs/reliability.md, "Hot-plug"). Removals
        // (the unplug's own events, which udev delivers after the read has
        // already failed) do not wake the reader.
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
        for (;;) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now()).count();
            std::vector<UdevEvent> events;
            if (mon_->wait(int(std::max<long long>(0, left)), &events) == 0) return false;
            for (const UdevEvent &e : events)
                if (e.action == "add") return true;
            if (left <= 0) return false;
        }
    }

    int get_feature(uint8_t *buf, size_t len, std::string &err) override {
        std::lock_guard<std::mutex> lock(mu_);
        if (!dev_) {
            err = "device disconnected";
            return CDM_ERR_DISCONNECTED;
        }
        const int n = hid_get_feature_report(dev_, buf, len);
        if (n < 0) {
            err = "hid_get_feature_report(" + report_id_text(buf[0]) + "): " + hid_err(dev_);
            return CDM_ERR_IO;
        }
        return n;
    }

    int send_feature(const uint8_t *buf, size_t len, std::string &err) override {
        std::lock_guard<std::mutex> lock(mu_);
        if (!dev_) {
            err = "device disconnected";
            return CDM_ERR_DISCONNECTED;
        }
        if (hid_send_feature_report(dev_, buf, len) < 0) {
            err = "hid_send_feature_report(" + report_id_text(buf[0]) + "): " + hid_err(dev_);
            return CDM_ERR_IO;
        }
        return CDM_OK;
    }

    int reopen(std::string &err) override {
        // By serial number: after a replug the kernel may give the device
        // another hidraw node. Without a serial, only the old path is left.
        const std::string path = serial_.empty() ? path_ : find_by_serial(serial_);
        if (path.empty()) {
            err = "no master with serial " + serial_ + " connected";
            return CDM_ERR_NO_DEVICE;
        }
        hid_device *d = nullptr;
        const int rc = checked_open(path, d, err);
        if (rc != CDM_OK) return rc;
        {
            std::lock_guard<std::mutex> lock(mu_);
            if (dev_) hid_close(dev_);
            dev_ = d;
            path_ = path;
        }
        mon_.reset(); // back: no more events wanted until the next unplug
        return CDM_OK;
    }

    const char *name() const override { return "hid"; }
    std::string uri() const override { return serial_.empty() ? "hid:" + path_ : "serial:" + serial_; }

private:
    std::mutex mu_;
    hid_device *dev_;
    std::string path_, serial_;
    std::unique_ptr<UdevMonitor> mon_; // while disconnected; reader thread only
};

// Opens the master at `path`, as given (a udev symlink stays the name a
// serial-less master is reconnected by, and a node with its own
// permissions is opened with them); when it names an enumerated master's
// node, the handle knows that master's serial and reconnects by it.
// serial: already known (the path came from find_by_serial): not looked up
// again.
int open_path(const std::string &path, const std::string &uri_text, TransportPtr &out, std::string &err,
              const std::string *serial = nullptr) {
    MasterNode node;
    if (serial) node.serial = *serial;
    const bool known = serial || master_named_by(path, node);
    std::string why;
    hid_device *d = nullptr;
    const int rc = checked_open(path, d, why);
    if (rc != CDM_OK) {
        err = "URI \"" + uri_text + "\": " + why + " (is it a master, and may this user open it? see udev/70-cdm.rules)";
        return rc;
    }
    out = std::make_unique<HidTransport>(d, path, known ? node.serial : std::string());
    return CDM_OK;
}

} // namespace

int open_hid(const Uri &u, TransportPtr &out, std::string &err) {
    int rc = ensure_hid_init(err);
    if (rc != CDM_OK) return rc;
    if (!u.options.empty()) {
        err = unknown_option(u, u.options[0].first, "none");
        return CDM_ERR_INVALID_ARG;
    }
    std::string serial;
    const bool by_serial = u.scheme == "serial" || u.path.rfind("serial=", 0) == 0;
    if (u.scheme == "serial") serial = u.path;
    else if (by_serial) serial = u.path.substr(7);
    if (by_serial) {
        if (serial.empty()) {
            err = "URI \"" + u.text + "\": empty serial number";
            return CDM_ERR_INVALID_ARG;
        }
        const std::string path = find_by_serial(serial);
        if (path.empty()) {
            err = "URI \"" + u.text + "\": no master (USB 1209:cd01) with serial " + serial + " is connected";
            return CDM_ERR_NO_DEVICE;
        }
        return open_path(path, u.text, out, err, &serial);
    }
    if (u.path.empty()) {
        err = "URI \"" + u.text + "\": hid: needs a path (hid:/dev/hidrawN) or a serial (hid:serial=SN)";
        return CDM_ERR_INVALID_ARG;
    }
    return open_path(u.path, u.text, out, err);
}

void hid_list_master_nodes(std::vector<MasterNode> &out, std::string &err) { out = master_nodes(err); }

bool hid_master_info(const MasterNode &node, cdm_device_info &out) {
    const std::string uri = "hid:" + node.path;
    cdm_device_info info{};
    bool full = false;
    hid_device *h = nullptr;
    std::string why;
    if (ensure_hid_init(why) == CDM_OK && checked_open(node.path, h, why) == CDM_OK) {
        uint8_t buf[proto::kDeviceInfoReportSize] = {proto::kDeviceInfoReportId};
        const int n = hid_get_feature_report(h, buf, sizeof buf);
        proto::DeviceInfoReport r;
        if (n > 0 && proto::parse_device_info(buf, size_t(n), r, nullptr) == proto::Reject::None) {
            device_info_from_report(r, "hid", uri, info);
            full = true;
        }
        hid_close(h);
    }
    if (!full) {
        // Busy or not answering: what enumeration knows (bcdDevice is
        // the firmware's major.minor).
        info.struct_size = sizeof info;
        std::snprintf(info.uri, sizeof info.uri, "%s", uri.c_str());
        std::snprintf(info.serial, sizeof info.serial, "%s", node.serial.c_str());
        std::snprintf(info.firmware, sizeof info.firmware, "%x.%x", node.release >> 8, node.release & 0xFF);
        std::snprintf(info.transport, sizeof info.transport, "hid");
    }
    info.vendor_id = proto::kVendorId;
    info.product_id = proto::kProductId;
    out = info;
    return full;
}

void hid_list_masters(std::vector<cdm_device_info> &out, std::string &err) {
    out.clear();
    std::vector<MasterNode> nodes;
    hid_list_master_nodes(nodes, err);
    for (const MasterNode &n : nodes) {
        cdm_device_info info;
        hid_master_info(n, info);
        out.push_back(info);
    }
}

} // namespace cdm

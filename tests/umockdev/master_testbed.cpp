#include "master_testbed.h"

#include <linux/hidraw.h>
#include <linux/input.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <umockdev.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <functional>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include "device/protocol.h"
#include "device/sim/firmware.h"
#include "device/sim/motion.h"
#include "device/sim/simulator.h"
#include "model/model.h"

namespace cdm_umock {

using namespace cdm::proto;

namespace {

// The tree the kernel (6.x, xHCI root hub at 0000:00:14.0, port 1) builds
// for the master; paths, attribute and property names as `udevadm info -a`
// and the uevent files show them on a real machine.
const char *const kUsbDev = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-1";
const char *const kUsbIntf = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-1/1-1:1.0";
const char *const kHidDev = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-1/1-1:1.0/0003:1209:CD01.0001";
const char *const kHidraw = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-1/1-1:1.0/0003:1209:CD01.0001/hidraw/hidraw0";

// USB descriptors as usbfs's `descriptors` attribute gives them (device
// descriptor, then the configuration with its interface, HID class and
// interrupt IN endpoint descriptors): libusb reads this file to enumerate.
std::vector<uint8_t> usb_descriptors() {
    const uint8_t dev[] = {18, 1, 0x00, 0x02, 0, 0, 0, 64, 0x09, 0x12, 0x01, 0xCD, 0x00, 0x01, 1, 2, 3, 1};
    std::vector<uint8_t> d(dev, dev + sizeof dev);
    const uint16_t rd = uint16_t(kReportDescriptorSize);
    const uint8_t cfg[] = {9, 2, 34, 0, 1, 1, 0, 0x80, 50,               // configuration, 34 bytes total
                           9, 4, 0, 0, 1, 3, 0, 0, 0,                    // interface 0, class HID
                           9, 0x21, 0x11, 0x01, 0, 1, 0x22, uint8_t(rd), uint8_t(rd >> 8), // HID 1.11
                           7, 5, 0x81, 3, 64, 0, 1};                     // EP 1 IN, interrupt, 64 bytes, 1 ms
    d.insert(d.end(), cfg, cfg + sizeof cfg);
    return d;
}

std::string hex_string(const uint8_t *b, size_t n) {
    std::string s;
    char t[3];
    for (size_t i = 0; i < n; ++i) {
        std::snprintf(t, sizeof t, "%02X", b[i]);
        s += t;
    }
    return s;
}

cdm::proto::DeviceInfoReport master_info(const TestbedOptions &o) {
    DeviceInfoReport info;
    info.fw_major = 1;
    info.fw_minor = 0;
    info.fw_patch = 0;
    info.adc_bits = 16;
    std::snprintf(info.serial, sizeof info.serial, "%s", o.serial.c_str());
    info.report_rate_hz = float(o.rate_hz);
    for (int i = 0; i < 4; ++i) {
        info.pot_scale_mm[i] = 0.01f;
        info.pot_offset_mm[i] = 0.0f;
    }
    const cdm::DeviceGeometry g;
    info.a_mm = float(g.a_mm);
    info.b_mm = float(g.b_mm);
    info.m_mm = float(g.m_mm);
    info.hall_closed = 2600;
    info.hall_open = 1400;
    info.grip_open_rad = 0.6f;
    return info;
}

} // namespace

struct MasterTestbed::Impl {
    TestbedOptions o;
    UMockdevTestbed *tb = nullptr;
    UMockdevIoctlBase *handler = nullptr;
    GMainContext *ctx = nullptr;
    GMainLoop *loop = nullptr;
    std::thread thread;
    GSource *tick = nullptr;

    // Everything below is touched only on the handler thread, except where
    // mu guards it (the test thread asks for truth and counters).
    cdm::sim::Firmware fw;
    cdm::sim::Simulator sim;
    std::deque<std::vector<uint8_t>> queue; // input reports the "kernel" holds (hidraw keeps 64)
    std::deque<UMockdevIoctlClient *> pending_reads;
    std::mt19937 garbage_rng{42};
    mutable std::mutex mu;
    std::map<uint32_t, cdm::SimTruth> truths;
    uint64_t sent = 0;
    std::map<unsigned, uint64_t> ioctl_count;
    std::atomic<bool> plugged{false};
    std::atomic<uint64_t> generation{1}; // bumped by unplug: clients of an older one get ENODEV (read by connected_cb, on any thread)

    explicit Impl(const TestbedOptions &opt)
        : o(opt), fw(master_info(opt)),
          sim(std::make_shared<cdm::Model>(cdm::DeviceGeometry{}), fw, cdm::sim::make_circle_motion(0.6),
              sensor_options(opt)) {}

    static cdm::sim::SensorOptions sensor_options(const TestbedOptions &o) {
        // Noise off: the only error left between truth and pose is the
        // 16-bit ADC's quantisation, which the test bounds exactly.
        cdm::sim::SensorOptions so;
        so.rate_hz = o.rate_hz;
        so.noise_mm = 0;
        so.imu_noise_rad = 0;
        so.hall_noise = 0;
        so.seed = 5;
        return so;
    }

    std::string tree_text(bool with_node) const;
    void add_tree();
    void write_readable_line();
    bool attached = false;
    void produce();
    void serve_reads();
    gboolean on_ioctl(UMockdevIoctlClient *c);
    gboolean on_read(UMockdevIoctlClient *c);
    gboolean on_write(UMockdevIoctlClient *c);
    void run_on_loop(std::function<void()> f);
};

// umockdev's record format: devices child first, E: properties, A: text
// attributes, H: binary attributes in hex, L: links, N: the /dev node.
std::string MasterTestbed::Impl::tree_text(bool with_node) const {
    const std::string sn = o.serial;
    const std::vector<uint8_t> desc = usb_descriptors();
    std::string t;
    t += std::string("P: ") + (kHidraw + 4) + (with_node ? "\nN: hidraw0" : "") + "\nE: DEVNAME=/dev/hidraw0\nE: MAJOR=243\nE: MINOR=0\n"
         "E: SUBSYSTEM=hidraw\nA: dev=243:0\n";
    // The kernel links every class device to its parent as `device`;
    // umockdev does not make that link by itself, and hidapi's filtered
    // enumeration reads <hidraw>/device/uevent through it.
    if (o.device_link) t += "L: device=../../../0003:1209:CD01.0001\n";
    t += "\n";
    char bus[8];
    std::snprintf(bus, sizeof bus, "%04X", o.hid_bus & 0xFFFFu);
    t += std::string("P: ") + (kHidDev + 4) + "\nE: DRIVER=hid-generic\nE: HID_ID=" + bus +
         ":00001209:0000CD01\nE: HID_NAME=pid.codes cdm haptic master\n"
         "E: HID_PHYS=usb-0000:00:14.0-1/input0\nE: HID_UNIQ=" + sn +
         "\nE: MODALIAS=hid:b" + bus + "g0001v00001209p0000CD01\nE: SUBSYSTEM=hid\n"
         "H: report_descriptor=" + hex_string(kReportDescriptor, kReportDescriptorSize) +
         "\nA: country=00\nL: driver=../../../../../../../bus/hid/drivers/hid-generic\n\n";
    t += std::string("P: ") + (kUsbIntf + 4) +
         "\nE: DEVTYPE=usb_interface\nE: DRIVER=usbhid\nE: PRODUCT=1209/cd01/100\nE: TYPE=0/0/0\n"
         "E: INTERFACE=3/0/0\nE: MODALIAS=usb:v1209pCD01d0100dc00dsc00dp00ic03isc00ip00in00\nE: SUBSYSTEM=usb\n"
         "A: bInterfaceNumber=00\nA: bInterfaceClass=03\nA: bInterfaceSubClass=00\nA: bInterfaceProtocol=00\n"
         "A: bNumEndpoints=01\nA: bAlternateSetting= 0\nA: modalias=usb:v1209pCD01d0100dc00dsc00dp00ic03isc00ip00in00\n"
         "L: driver=../../../../../../bus/usb/drivers/usbhid\n\n";
    t += std::string("P: ") + (kUsbDev + 4) +
         "\nN: bus/usb/001/002\nE: DEVNAME=/dev/bus/usb/001/002\nE: DEVTYPE=usb_device\nE: DRIVER=usb\n"
         "E: PRODUCT=1209/cd01/100\nE: TYPE=0/0/0\nE: BUSNUM=001\nE: DEVNUM=002\nE: MAJOR=189\nE: MINOR=1\n"
         "E: SUBSYSTEM=usb\nE: ID_VENDOR_ID=1209\nE: ID_MODEL_ID=cd01\nE: ID_SERIAL_SHORT=" + sn +
         "\nA: idVendor=1209\nA: idProduct=cd01\nA: bcdDevice=0100\nA: manufacturer=pid.codes\n"
         "A: product=cdm haptic master\nA: serial=" + sn +
         "\nA: busnum=1\nA: devnum=2\nA: speed=12\nA: bDeviceClass=00\nA: bNumConfigurations=1\n"
         "A: bConfigurationValue=1\nA: dev=189:1\nH: descriptors=" + hex_string(desc.data(), desc.size()) +
         "\nL: driver=../../../../../bus/usb/drivers/usb\n";
    return t;
}

void MasterTestbed::Impl::add_tree() {
    GError *e = nullptr;
    // One device at a time, parents first: umockdev sends each device's
    // "add" uevent as it adds it, and the kernel announces the USB device
    // first and the hidraw node last, once everything under it exists. The
    // whole text at once would announce hidraw0 before its parents'
    // attributes are there (umockdev's record format lists children
    // first), an order no kernel produces.
    // A replug: the node answers before the first uevent goes out, as a
    // kernel's hidraw node does by the time udev announces it. umockdev
    // serves ioctls while it adds devices (the handler's context runs
    // during the add), so an "add" watcher that opens at once would
    // otherwise meet ENODEV and wait for its next retry.
    if (attached) {
        write_readable_line();
        plugged = true;
    }
    const std::string text = tree_text(!attached);
    std::vector<std::string> blocks;
    for (size_t at = 0; at < text.size();) {
        size_t end = text.find("\n\n", at);
        if (end == std::string::npos) end = text.size();
        blocks.push_back(text.substr(at, end - at) + "\n");
        at = end + 2;
    }
    for (auto it = blocks.rbegin(); it != blocks.rend(); ++it) {
        if (!umockdev_testbed_add_from_string(tb, it->c_str(), &e)) {
            std::string m = e ? e->message : "unknown";
            g_clear_error(&e);
            throw std::runtime_error("umockdev_testbed_add_from_string: " + m);
        }
    }
    // The ioctl socket must be served by the handler thread's context: it
    // is the thread-default one while attaching.
    // Attached once for the testbed's life: umockdev's preload ends the
    // client process when an open fd's socket disappears, which a detach
    // on unplug would do to the driver's handle under test.
    if (attached) return;
    g_main_context_push_thread_default(ctx);
    const gboolean ok = umockdev_testbed_attach_ioctl(tb, "/dev/hidraw0", handler, &e);
    g_main_context_pop_thread_default(ctx);
    if (!ok) {
        std::string m = e ? e->message : "unknown";
        g_clear_error(&e);
        throw std::runtime_error("umockdev_testbed_attach_ioctl: " + m);
    }
    // umockdev backs a character device node with a pty: the client's
    // poll() (hidapi polls before every read) sees the pty, while its
    // read() comes to on_read. One line on the pty's master side makes the
    // node readable for good; on_read then blocks until the next report, as
    // hidraw's read does. (hidraw signals data by POLLIN, an unplug by
    // POLLHUP; the pty gives POLLHUP too once umockdev closes its master.)
    attached = true;
    write_readable_line();
    plugged = true;
}

void MasterTestbed::Impl::write_readable_line() {
    const int fd = umockdev_testbed_get_dev_fd(tb, "/dev/hidraw0");
    if (fd < 0 || write(fd, "\n", 1) != 1) throw std::runtime_error("cannot make /dev/hidraw0 readable");
}

// One sample period: the firmware samples and sends one input report; the
// kernel queues it (dropping the oldest past 64, as hidraw does) and hands
// it to a waiting reader.
void MasterTestbed::Impl::produce() {
    std::vector<uint8_t> r(kInputReportSize);
    if (!plugged) {
        // A self-powered master keeps sampling while its cable is out: its
        // sequence runs on, and the host sees the gap after the replug.
        cdm::SimTruth t;
        if (o.mode != NodeMode::Garbage) sim.next(r.data(), t);
        return;
    }
    if (o.mode == NodeMode::Garbage) {
        for (auto &b : r) b = uint8_t(garbage_rng());
    } else {
        cdm::SimTruth t;
        if (!sim.next(r.data(), t)) return;
        std::lock_guard<std::mutex> lock(mu);
        truths[t.sequence] = t;
        if (truths.size() > 20000) truths.erase(truths.begin());
        ++sent;
    }
    queue.push_back(std::move(r));
    if (queue.size() > 64) queue.pop_front();
    serve_reads();
}

void MasterTestbed::Impl::serve_reads() {
    while (!pending_reads.empty()) {
        UMockdevIoctlClient *c = pending_reads.front();
        const uint64_t gen = GPOINTER_TO_SIZE(g_object_get_data(G_OBJECT(c), "cdm-generation"));
        if (gen != generation) {
            pending_reads.pop_front();
            umockdev_ioctl_client_complete(c, -1, ENODEV);
            g_object_unref(c);
            continue;
        }
        if (queue.empty()) return;
        pending_reads.pop_front();
        UMockdevIoctlData *arg = umockdev_ioctl_client_get_arg(c);
        std::vector<uint8_t> &r = queue.front();
        const size_t n = std::min(r.size(), size_t(arg->data_len));
        umockdev_ioctl_data_update(arg, 0, r.data(), gint(n));
        queue.pop_front();
        umockdev_ioctl_client_complete(c, glong(n), 0);
        g_object_unref(c);
    }
}

namespace {

uint64_t client_generation(UMockdevIoctlClient *c) {
    return GPOINTER_TO_SIZE(g_object_get_data(G_OBJECT(c), "cdm-generation"));
}

// umockdev emits a client's signals partly on the handler thread (whose
// context was the thread default when the handler was attached) and partly
// on a thread of GLib's own: about 35 of a umockdev_watch run's, counted.
// An ASan run caught on_read popping the report queue there while unplug()
// cleared it on the handler thread (a double free, once in 65 runs). A signal that
// arrives elsewhere is therefore handed to the handler thread (the client
// is completed from there, as a pending read always was), so that the
// state below is touched on that thread alone, as Impl says.
template <gboolean (MasterTestbed::Impl::*On)(UMockdevIoctlClient *)>
gboolean on_handler_thread(UMockdevIoctlClient *c, gpointer self) {
    auto *impl = static_cast<MasterTestbed::Impl *>(self);
    if (g_main_context_is_owner(impl->ctx)) return (impl->*On)(c);
    struct Hop {
        MasterTestbed::Impl *impl;
        UMockdevIoctlClient *c;
    };
    auto *h = new Hop{impl, G_TYPE_CHECK_INSTANCE_CAST(g_object_ref(c), UMOCKDEV_TYPE_IOCTL_CLIENT, UMockdevIoctlClient)};
    g_main_context_invoke_full(
        impl->ctx, G_PRIORITY_DEFAULT,
        [](gpointer p) -> gboolean {
            auto *k = static_cast<Hop *>(p);
            (k->impl->*On)(k->c);
            return G_SOURCE_REMOVE;
        },
        h,
        [](gpointer p) {
            auto *k = static_cast<Hop *>(p);
            g_object_unref(k->c);
            delete k;
        });
    return TRUE;
}
gboolean ioctl_cb(UMockdevIoctlBase *, UMockdevIoctlClient *c, gpointer self) {
    return on_handler_thread<&MasterTestbed::Impl::on_ioctl>(c, self);
}
gboolean read_cb(UMockdevIoctlBase *, UMockdevIoctlClient *c, gpointer self) {
    return on_handler_thread<&MasterTestbed::Impl::on_read>(c, self);
}
gboolean write_cb(UMockdevIoctlBase *, UMockdevIoctlClient *c, gpointer self) {
    return on_handler_thread<&MasterTestbed::Impl::on_write>(c, self);
}
void connected_cb(UMockdevIoctlBase *, UMockdevIoctlClient *c, gpointer self) {
    // A client belongs to the plug it opened: after an unplug its fd is
    // dead, as a real hidraw fd is, even if the device comes back.
    g_object_set_data(G_OBJECT(c), "cdm-generation",
                      GSIZE_TO_POINTER(static_cast<MasterTestbed::Impl *>(self)->generation));
}
gboolean tick_cb(gpointer self) {
    static_cast<MasterTestbed::Impl *>(self)->produce();
    return G_SOURCE_CONTINUE;
}

// Resolves the ioctl's argument (a user pointer) to `len` bytes of the
// client's memory; null on failure.
UMockdevIoctlData *resolve(UMockdevIoctlClient *c, size_t len) {
    GError *e = nullptr;
    UMockdevIoctlData *d = umockdev_ioctl_data_resolve(umockdev_ioctl_client_get_arg(c), 0, len, &e);
    if (e) {
        g_warning("resolving ioctl data: %s", e->message);
        g_clear_error(&e);
    }
    return d;
}

} // namespace

gboolean MasterTestbed::Impl::on_ioctl(UMockdevIoctlClient *c) {
    const unsigned long req = umockdev_ioctl_client_get_request(c);
    const unsigned type = _IOC_TYPE(req), nr = _IOC_NR(req), size = _IOC_SIZE(req);
    if (type == 'H') {
        std::lock_guard<std::mutex> lock(mu);
        ++ioctl_count[nr];
    }
    if (!plugged || client_generation(c) != generation) {
        umockdev_ioctl_client_complete(c, -1, ENODEV);
        return TRUE;
    }
    if (type != 'H' || o.mode == NodeMode::NoIoctl) {
        umockdev_ioctl_client_complete(c, -1, ENOTTY);
        return TRUE;
    }
    // Numbers and semantics from linux/hidraw.h and drivers/hid/hidraw.c.
    if (req == HIDIOCGRDESCSIZE) {
        UMockdevIoctlData *d = resolve(c, sizeof(int));
        if (!d) return umockdev_ioctl_client_complete(c, -1, EFAULT), TRUE;
        const int n = o.mode == NodeMode::Garbage ? 4096 : int(kReportDescriptorSize);
        std::memcpy(d->data, &n, sizeof n);
        umockdev_ioctl_client_complete(c, 0, 0);
        return TRUE;
    }
    if (req == HIDIOCGRDESC) {
        UMockdevIoctlData *d = resolve(c, sizeof(hidraw_report_descriptor));
        if (!d) return umockdev_ioctl_client_complete(c, -1, EFAULT), TRUE;
        auto *rd = reinterpret_cast<hidraw_report_descriptor *>(d->data);
        // The kernel refuses a size over HID_MAX_DESCRIPTOR_SIZE or over
        // the descriptor's own length.
        if (rd->size > HID_MAX_DESCRIPTOR_SIZE || rd->size > kReportDescriptorSize) {
            umockdev_ioctl_client_complete(c, -1, EINVAL);
            return TRUE;
        }
        std::memcpy(rd->value, kReportDescriptor, rd->size);
        umockdev_ioctl_client_complete(c, 0, 0);
        return TRUE;
    }
    if (req == HIDIOCGRAWINFO) {
        UMockdevIoctlData *d = resolve(c, sizeof(hidraw_devinfo));
        if (!d) return umockdev_ioctl_client_complete(c, -1, EFAULT), TRUE;
        hidraw_devinfo info{};
        info.bustype = BUS_USB;
        info.vendor = int16_t(kVendorId);
        info.product = int16_t(kProductId);
        std::memcpy(d->data, &info, sizeof info);
        umockdev_ioctl_client_complete(c, 0, 0);
        return TRUE;
    }
    if (nr == 0x04 || nr == 0x05) { // HIDIOCGRAWNAME(len), HIDIOCGRAWPHYS(len)
        const std::string s = nr == 0x04 ? "pid.codes cdm haptic master" : "usb-0000:00:14.0-1/input0";
        UMockdevIoctlData *d = resolve(c, size);
        if (!d) return umockdev_ioctl_client_complete(c, -1, EFAULT), TRUE;
        const size_t n = std::min<size_t>(s.size() + 1, size);
        std::memcpy(d->data, s.c_str(), n);
        umockdev_ioctl_client_complete(c, glong(n), 0);
        return TRUE;
    }
    if (nr == 0x06 || nr == 0x07) { // HIDIOCSFEATURE(len), HIDIOCGFEATURE(len)
        UMockdevIoctlData *d = resolve(c, size);
        if (!d || size == 0) return umockdev_ioctl_client_complete(c, -1, EFAULT), TRUE;
        if (o.mode == NodeMode::Garbage) {
            for (unsigned i = 1; i < size; ++i) d->data[i] = uint8_t(garbage_rng());
            umockdev_ioctl_client_complete(c, glong(size), 0);
            return TRUE;
        }
        // The device STALLs what it refuses: usbhid turns that into EPIPE.
        const int n = nr == 0x07 ? fw.get_feature(d->data, size) : fw.send_feature(d->data, size);
        if (n < 0) umockdev_ioctl_client_complete(c, -1, EPIPE);
        else umockdev_ioctl_client_complete(c, nr == 0x07 ? glong(n) : glong(size), 0);
        return TRUE;
    }
    umockdev_ioctl_client_complete(c, -1, EINVAL); // hidraw's answer to an unknown 'H' ioctl
    return TRUE;
}

gboolean MasterTestbed::Impl::on_read(UMockdevIoctlClient *c) {
    if (!plugged || client_generation(c) != generation) {
        umockdev_ioctl_client_complete(c, -1, ENODEV);
        return TRUE;
    }
    if (o.mode == NodeMode::NoIoctl) {
        umockdev_ioctl_client_complete(c, 0, 0);
        return TRUE;
    }
    // Blocks, as hidraw's read does, until the next report.
    pending_reads.push_back(G_TYPE_CHECK_INSTANCE_CAST(g_object_ref(c), UMOCKDEV_TYPE_IOCTL_CLIENT,
                                                       UMockdevIoctlClient));
    serve_reads();
    return TRUE;
}

gboolean MasterTestbed::Impl::on_write(UMockdevIoctlClient *c) {
    // The master has no output report: hidraw sends the write down the
    // control pipe as SET_REPORT(Output), which the device STALLs.
    umockdev_ioctl_client_complete(c, -1, EPIPE);
    return TRUE;
}

void MasterTestbed::Impl::run_on_loop(std::function<void()> f) {
    std::mutex m;
    std::condition_variable cv;
    bool done = false;
    struct Call {
        std::function<void()> *f;
        std::mutex *m;
        std::condition_variable *cv;
        bool *done;
    } call{&f, &m, &cv, &done};
    g_main_context_invoke(
        ctx,
        [](gpointer p) -> gboolean {
            auto *k = static_cast<Call *>(p);
            (*k->f)();
            std::lock_guard<std::mutex> lock(*k->m);
            *k->done = true;
            k->cv->notify_all();
            return G_SOURCE_REMOVE;
        },
        &call);
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return done; });
}

MasterTestbed::MasterTestbed(const TestbedOptions &o) : p_(std::make_unique<Impl>(o)) {
    if (!in_mock_environment())
        throw std::runtime_error("not under umockdev's preload: run through umockdev-wrapper");
    p_->tb = umockdev_testbed_new();
    p_->handler = umockdev_ioctl_base_new();
    g_signal_connect(p_->handler, "handle-ioctl", G_CALLBACK(ioctl_cb), p_.get());
    g_signal_connect(p_->handler, "handle-read", G_CALLBACK(read_cb), p_.get());
    g_signal_connect(p_->handler, "handle-write", G_CALLBACK(write_cb), p_.get());
    g_signal_connect(p_->handler, "client-connected", G_CALLBACK(connected_cb), p_.get());
    p_->ctx = g_main_context_new();
    p_->loop = g_main_loop_new(p_->ctx, FALSE);
    p_->add_tree();
    p_->tick = g_timeout_source_new(guint(1000.0 / o.rate_hz + 0.5));
    g_source_set_callback(p_->tick, tick_cb, p_.get(), nullptr);
    g_source_attach(p_->tick, p_->ctx);
    p_->thread = std::thread([this] {
        g_main_context_push_thread_default(p_->ctx);
        g_main_loop_run(p_->loop);
        g_main_context_pop_thread_default(p_->ctx);
    });
}

MasterTestbed::~MasterTestbed() {
    p_->run_on_loop([this] {
        p_->plugged = false;
        ++p_->generation;
        p_->serve_reads();
        g_source_destroy(p_->tick);
    });
    g_main_loop_quit(p_->loop);
    p_->thread.join();
    g_source_unref(p_->tick);
    g_object_unref(p_->tb); // removes the testbed's directory
    g_object_unref(p_->handler);
    g_main_loop_unref(p_->loop);
    g_main_context_unref(p_->ctx);
}

void MasterTestbed::unplug() {
    p_->run_on_loop([this] {
        if (!p_->plugged) return;
        p_->plugged = false;
        ++p_->generation;
        p_->queue.clear();
        // Tree and node go first, then the open fd's pending read fails:
        // the driver reacts to the failed read by reopening at once, and
        // must find no node then, as on a real unplug.
        for (const char *path : {kHidraw, kHidDev, kUsbIntf, kUsbDev}) umockdev_testbed_uevent(p_->tb, path, "remove");
        // umockdev 0.17.16 cannot give a removed device's node back: its
        // pty stays registered and a re-add with the same node asserts. So
        // the tree goes (the USB device's removal takes the children's
        // directories; their /sys/class and /sys/dev links are dropped by
        // hand, or the re-add fails on them) and the node stays, answering
        // ENODEV to everything until the replug, as an fd of an unplugged
        // hidraw device does. What a reopen meets meanwhile is therefore a
        // node without sysfs device: the case the driver must check for
        // before calling hid_open_path (hidapi 0.13.1 crashes there).
        umockdev_testbed_remove_device(p_->tb, kUsbDev);
        const std::string root = umockdev_testbed_get_root_dir(p_->tb);
        for (const char *l : {"/sys/class/hidraw/hidraw0", "/sys/dev/char/243:0", "/sys/bus/hid/devices/0003:1209:CD01.0001",
                              "/sys/bus/usb/devices/1-1:1.0", "/sys/bus/usb/devices/1-1", "/dev/.node/hidraw0"})
            unlink((root + l).c_str());
        p_->serve_reads(); // pending reads fail with ENODEV
    });
}

void MasterTestbed::plug() {
    p_->run_on_loop([this] {
        if (!p_->plugged) p_->add_tree();
    });
}

bool MasterTestbed::plugged() const { return p_->plugged; }

bool MasterTestbed::truth(uint32_t seq, cdm::SimTruth &out) const {
    std::lock_guard<std::mutex> lock(p_->mu);
    auto it = p_->truths.find(seq);
    if (it == p_->truths.end()) return false;
    out = it->second;
    return true;
}

uint64_t MasterTestbed::reports_sent() const {
    std::lock_guard<std::mutex> lock(p_->mu);
    return p_->sent;
}

uint64_t MasterTestbed::ioctls_seen(unsigned nr) const {
    std::lock_guard<std::mutex> lock(p_->mu);
    auto it = p_->ioctl_count.find(nr);
    return it == p_->ioctl_count.end() ? 0 : it->second;
}

const std::string &MasterTestbed::hidraw_syspath() const {
    static const std::string s = kHidraw;
    return s;
}

// umockdev_in_mock_environment() only turns true once a testbed exists; the
// question here is whether one can work, i.e. whether the preload is there.
bool in_mock_environment() {
    const char *pre = std::getenv("LD_PRELOAD");
    return pre && std::strstr(pre, "libumockdev-preload") != nullptr;
}

} // namespace cdm_umock

// One interface for every way reports reach the driver (the real device
// through hidapi, the simulated master, a recording), and the registry that
// lists them. The reader thread (device.cpp) sees only this interface; the
// bytes it gets are parsed by the one parser in protocol.cpp whatever their
// origin.
//
// Adding a transport = one file implementing Transport plus an opener, and
// one line in kTransports (transport_registry.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace cdm {

// A parsed device URI: "scheme:path?k=v&k=v" ("/dev/hidrawN" alone means
// "hid:/dev/hidrawN"). docs/protocol.md lists the schemes and options.
struct Uri {
    std::string text;   // as given
    std::string scheme; // "hid", "serial", "sim", "replay"
    std::string path;   // between ':' and '?'
    std::vector<std::pair<std::string, std::string>> options; // in order, keys unique
};
// Longest URI accepted: a path (PATH_MAX is 4096) and every sim: option
// with long fault lists fit many times over.
constexpr size_t kMaxUriBytes = 65536;
// Returns CDM_OK or a cdm_error (NO_DEVICE for a string that is no URI,
// INVALID_ARG for a malformed option list or a URI past kMaxUriBytes) with
// err naming the culprit.
int parse_uri(const std::string &text, Uri &out, std::string &err);

// "0x1f": a report ID as the transports' error messages name it.
std::string report_id_text(uint8_t id);

// Transport::read results besides a byte count > 0.
enum ReadStatus : int {
    kReadTimeout = 0,       // nothing within timeout_ms
    kReadDisconnected = -1, // device gone (unplugged); the reader calls reopen() until it is back
    kReadEnd = -2,          // scripted stream finished (replay, sim jig): no more reports, ever
    kReadError = -3,        // transport failure; err says what. The reader treats it as a disconnection.
};

class Transport {
public:
    virtual ~Transport() = default;

    // MANDATORY. Called only from the reader thread. One input report, report
    // ID first, into buf (capacity cap); waits at most timeout_ms. Returns
    // its length or a ReadStatus.
    virtual int read(uint8_t *buf, size_t cap, int timeout_ms, std::string &err) = 0;

    // MANDATORY. GET_REPORT(Feature): buf[0] holds the report ID on entry.
    // Returns the length received (report ID included) or a negative
    // cdm_error with err set. Any thread (transports serialise internally).
    virtual int get_feature(uint8_t *buf, size_t len, std::string &err) = 0;

    // MANDATORY. "hid", "sim" or "replay", and a URI cdm_open accepts for
    // this very device.
    virtual const char *name() const = 0;
    virtual std::string uri() const = 0;

    // OPTIONAL (default: CDM_ERR_UNSUPPORTED). SET_REPORT(Feature), buf[0] =
    // report ID. Returns CDM_OK or a negative cdm_error. Any thread.
    virtual int send_feature(const uint8_t *buf, size_t len, std::string &err);

    // OPTIONAL (default: CDM_ERR_UNSUPPORTED, the handle stays disconnected).
    // Called from the reader thread after kReadDisconnected/kReadError, every
    // ~250 ms: one attempt to reopen the same device (same serial number).
    virtual int reopen(std::string &err);

    // OPTIONAL (default: sleeps timeout_ms, returns false). Called from the
    // reader thread between reconnection attempts: waits at most timeout_ms
    // for a sign that the device may be back (hid: udev's hot-plug event,
    // device/hotplug.h); true if one came, and the reader tries reopen() at
    // once instead of at the next retry tick.
    virtual bool wait_arrival(int timeout_ms);

    // OPTIONAL (default: none). Something the caller should know although
    // the open succeeded (a recording cut short: its tail was dropped).
    // cdm_open puts it into cdm_device_error; truncated_bytes goes into
    // cdm_stats.replay_truncated_bytes.
    virtual std::string open_warning() const { return {}; }
    // OPTIONAL (default: false, live). After a read(): whether the report
    // comes from a recording, and the host time it was first received at
    // (0 is a time like any other), so that re-recording a replay keeps its
    // times (cdm_sample.source_time_ns) and its counters come out as the
    // recorded device's.
    virtual bool plays_recording() const { return false; }
    virtual uint64_t record_time_ns() const { return 0; }
    virtual uint64_t truncated_bytes() const { return 0; }
};

using TransportPtr = std::unique_ptr<Transport>;
using TransportOpenFn = int (*)(const Uri &uri, TransportPtr &out, std::string &err);

struct TransportEntry {
    const char *scheme;
    const char *usage; // one line for error messages and `cdm --help`
    TransportOpenFn open;
};

// The registry: every scheme cdm_open knows, in one table.
const TransportEntry *find_transport(const std::string &scheme);
const std::vector<TransportEntry> &transports();

// Option helpers shared by the transports: values are checked strictly and
// an error names the option, the value and the URI.
bool option_double(const Uri &u, const std::string &key, const std::string &value, double lo, double hi,
                   double &out, std::string &err);
bool option_u64(const Uri &u, const std::string &key, const std::string &value, uint64_t lo, uint64_t hi,
                uint64_t &out, std::string &err);
std::string unknown_option(const Uri &u, const std::string &key, const char *known);

} // namespace cdm

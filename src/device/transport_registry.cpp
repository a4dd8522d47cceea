#include <cstdio>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <set>
#include <thread>

#include "cdm/cdm.h"
#include "device/transport.h"
#include "io/text.h"

namespace cdm {

// Openers live beside their transports.
int open_hid(const Uri &uri, TransportPtr &out, std::string &err);
int open_sim(const Uri &uri, TransportPtr &out, std::string &err);
int open_replay(const Uri &uri, TransportPtr &out, std::string &err);

const std::vector<TransportEntry> &transports() {
    static const std::vector<TransportEntry> table = {
        {"hid", "hid:/dev/hidrawN | /dev/hidrawN | hid:serial=SN", open_hid},
        {"serial", "serial:SN", open_hid},
        {"sim", "sim: | sim:?rate=1000&noise=0.05&seed=1&motion=random|still|circle|jig&...", open_sim},
        {"replay", "replay:FILE | replay:FILE?speed=0", open_replay},
    };
    return table;
}

const TransportEntry *find_transport(const std::string &scheme) {
    for (const auto &t : transports())
        if (scheme == t.scheme) return &t;
    return nullptr;
}

int Transport::send_feature(const uint8_t *, size_t, std::string &err) {
    err = std::string(name()) + " transport cannot send feature reports";
    return CDM_ERR_UNSUPPORTED;
}

int Transport::reopen(std::string &err) {
    err = std::string(name()) + " transport cannot reconnect";
    return CDM_ERR_UNSUPPORTED;
}

bool Transport::wait_arrival(int timeout_ms) {
    std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
    return false;
}

std::string report_id_text(uint8_t id) {
    char b[8];
    std::snprintf(b, sizeof b, "0x%02x", unsigned(id));
    return b;
}

int parse_uri(const std::string &text, Uri &out, std::string &err) {
    if (text.size() > kMaxUriBytes) {
        err = "a device URI of " + std::to_string(text.size()) + " bytes (at most " + std::to_string(kMaxUriBytes) +
              "): \"" + text.substr(0, 64) + "...\"";
        return CDM_ERR_INVALID_ARG;
    }
    Uri u;
    u.text = text;
    std::string rest;
    if (!text.empty() && text[0] == '/') {
        u.scheme = "hid";
        rest = text;
    } else {
        const size_t colon = text.find(':');
        bool ok = colon != std::string::npos && colon > 0;
        for (size_t i = 0; ok && i < colon; ++i) {
            const char c = text[i];
            ok = (c >= 'a' && c <= 'z') || (i > 0 && c >= '0' && c <= '9');
        }
        if (!ok) {
            err = "\"" + text + "\" is not a device URI (expected scheme:..., e.g. sim:, replay:FILE, hid:/dev/hidraw0)";
            return CDM_ERR_NO_DEVICE;
        }
        u.scheme = text.substr(0, colon);
        rest = text.substr(colon + 1);
    }
    const size_t q = rest.find('?');
    u.path = rest.substr(0, q);
    if (q != std::string::npos) {
        const std::string query = rest.substr(q + 1);
        std::set<std::string> seen; // a repeat found in O(log n), not by a scan of the options
        size_t start = 0;
        while (start < query.size()) {
            size_t end = query.find('&', start);
            if (end == std::string::npos) end = query.size();
            const std::string item = query.substr(start, end - start);
            const size_t eq = item.find('=');
            if (item.empty() || eq == std::string::npos || eq == 0) {
                err = "URI \"" + text + "\": option \"" + item + "\" is not of the form name=value";
                return CDM_ERR_INVALID_ARG;
            }
            const std::string key = item.substr(0, eq);
            if (!seen.insert(key).second) {
                err = "URI \"" + text + "\": option \"" + key + "\" given twice";
                return CDM_ERR_INVALID_ARG;
            }
            u.options.emplace_back(key, item.substr(eq + 1));
            start = end + 1;
        }
    }
    out = u;
    return CDM_OK;
}

bool option_double(const Uri &u, const std::string &key, const std::string &value, double lo, double hi,
                   double &out, std::string &err) {
    char *end = nullptr;
    errno = 0;
    const double v = value.empty() ? 0.0 : std::strtod(value.c_str(), &end);
    if (value.empty() || errno != 0 || *end != '\0' || !(v >= lo && v <= hi)) {
        err = "URI \"" + u.text + "\": option " + key + "=\"" + value + "\" must be a number in [" +
              io::number_text(lo) + ", " + io::number_text(hi) + "]";
        return false;
    }
    out = v;
    return true;
}

bool option_u64(const Uri &u, const std::string &key, const std::string &value, uint64_t lo, uint64_t hi,
                uint64_t &out, std::string &err) {
    char *end = nullptr;
    errno = 0;
    const bool digits = !value.empty() && value.find_first_not_of("0123456789") == std::string::npos;
    const unsigned long long v = digits ? std::strtoull(value.c_str(), &end, 10) : 0;
    if (!digits || errno != 0 || v < lo || v > hi) {
        err = "URI \"" + u.text + "\": option " + key + "=\"" + value + "\" must be an integer in [" +
              std::to_string(lo) + ", " + std::to_string(hi) + "]";
        return false;
    }
    out = v;
    return true;
}

std::string unknown_option(const Uri &u, const std::string &key, const char *known) {
    return "URI \"" + u.text + "\": unknown option \"" + key + "\" (known: " + known + ")";
}

} // namespace cdm

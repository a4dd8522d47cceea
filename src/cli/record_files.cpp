// See record_files.h.
#include "record_files.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "commands.h"

namespace cdm::cli {

std::vector<std::pair<std::string, std::string>> uri_options(const std::string &uri) {
    std::vector<std::pair<std::string, std::string>> v;
    const size_t q = uri.find('?');
    if (q == std::string::npos) return v;
    for (size_t i = q + 1; i < uri.size();) {
        size_t e = uri.find('&', i);
        if (e == std::string::npos) e = uri.size();
        const std::string opt = uri.substr(i, e - i);
        const size_t eq = opt.find('=');
        v.emplace_back(opt.substr(0, eq), eq == std::string::npos ? "" : opt.substr(eq + 1));
        i = e + 1;
    }
    return v;
}

std::vector<std::string> uri_inputs(const std::string &uri) {
    std::vector<std::string> v;
    const size_t q = uri.find('?');
    if (uri.rfind("replay:", 0) == 0) v.push_back(uri.substr(7, q == std::string::npos ? q : q - 7));
    for (const auto &[k, value] : uri_options(uri))
        if (k == "device" || k == "truth" || k == "jig_plan") v.push_back(value);
    return v;
}

bool unpaced(const std::string &uri) {
    const char *key = uri.rfind("sim:", 0) == 0 ? "realtime" : uri.rfind("replay:", 0) == 0 ? "speed" : nullptr;
    if (!key) return false;
    for (const auto &[k, value] : uri_options(uri))
        if (k == key) {
            char *end = nullptr;
            const double d = std::strtod(value.c_str(), &end);
            return !value.empty() && *end == '\0' && d == 0;
        }
    return false;
}

void check_output(const std::string &uri, const std::string &file, const std::vector<std::string> &also) {
    struct stat out {};
    for (const std::string &p : {file, file + ".tmp"}) {
        if (stat(p.c_str(), &out) != 0) continue;
        if (!S_ISREG(out.st_mode)) throw UsageError(p + " exists and is not a regular file: not writing over it");
        for (const auto &in : uri_inputs(uri))
            if (same_file(in, p)) throw UsageError(p + " is the input " + in + " of " + uri + ": not writing over it");
        for (const auto &in : also)
            if (same_file(in, p)) throw UsageError(p + " is the input " + in + " of this command: not writing over it");
    }
}

// The recorder writes to FILE.tmp, whose own extension says nothing: the
// format comes from FILE's.
const char *format_of(const std::string &file) {
    auto ends = [&](const char *x) {
        const size_t n = std::strlen(x);
        if (file.size() < n) return false;
        for (size_t i = 0; i < n; ++i)
            if (std::tolower(static_cast<unsigned char>(file[file.size() - n + i])) != x[i]) return false;
        return true;
    };
    return ends(".mcap") ? "mcap" : ends(".csv") ? "csv" : "cdmrec";
}

std::string sync_file(const std::string &path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::fsync(fd) != 0) {
        const std::string why = path + ": fsync: " + std::strerror(errno);
        if (fd >= 0) ::close(fd);
        return why;
    }
    ::close(fd);
    return "";
}

} // namespace cdm::cli

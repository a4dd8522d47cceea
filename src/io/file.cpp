#include "io/file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace cdm::io {

namespace {
std::string why() { return std::strerror(errno); }

std::string dir_of(const std::string &path) {
    auto s = path.find_last_of('/');
    if (s == std::string::npos) return ".";
    if (s == 0) return "/";
    return path.substr(0, s);
}

std::string base_of(const std::string &path) {
    auto s = path.find_last_of('/');
    return s == std::string::npos ? path : path.substr(s + 1);
}

bool fsync_dir(const std::string &dir, std::string &err) {
    int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (d < 0) {
        err = dir + ": cannot open the directory to sync it: " + why();
        return false;
    }
    // EINVAL: the file system does not sync directories; the rename stands.
    const bool ok = ::fsync(d) == 0 || errno == EINVAL;
    if (!ok) err = dir + ": cannot sync the directory: " + why();
    ::close(d);
    return ok;
}
} // namespace

const char *file_kind(mode_t m) {
    if (S_ISREG(m)) return "a regular file";
    if (S_ISDIR(m)) return "a directory";
    if (S_ISFIFO(m)) return "a FIFO (named pipe)";
    if (S_ISCHR(m)) return "a character device";
    if (S_ISBLK(m)) return "a block device";
    if (S_ISSOCK(m)) return "a socket";
    return "a file of unknown kind";
}

FileReader::~FileReader() {
    if (fd_ >= 0) ::close(fd_);
}

bool FileReader::open(const std::string &path, size_t max_bytes, std::string &err, const char *what) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    // O_NONBLOCK: opening a FIFO without a writer must not hang; fstat then
    // refuses it (and every other special file) before any read.
    int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        err = path + ": cannot open the " + what + ": " + why();
        return false;
    }
    struct stat st;
    if (::fstat(fd, &st) != 0) {
        err = path + ": cannot stat the " + what + ": " + why();
        ::close(fd);
        return false;
    }
    if (!S_ISREG(st.st_mode)) {
        err = path + ": the " + std::string(what) + " is " + file_kind(st.st_mode) + ", not a regular file";
        ::close(fd);
        return false;
    }
    if (size_t(st.st_size) > max_bytes) {
        err = path + ": the " + std::string(what) + " is " + std::to_string(st.st_size) + " bytes, more than the " +
              std::to_string(max_bytes) + "-byte limit";
        ::close(fd);
        return false;
    }
    fd_ = fd;
    max_ = max_bytes;
    path_ = path;
    what_ = what;
    return true;
}

long FileReader::pread(char *buf, size_t n, size_t offset, std::string &err) const {
    // The file may grow while read: read to EOF but never past the cap
    // (one byte beyond it tells a file that grew past it).
    if (offset > max_) {
        err = path_ + ": the " + what_ + " grew past the " + std::to_string(max_) + "-byte limit while being read";
        return -1;
    }
    n = std::min(n, max_ + 1 - offset);
    for (;;) {
        ssize_t r = ::pread(fd_, buf, n, off_t(offset));
        if (r < 0) {
            if (errno == EINTR) continue;
            err = path_ + ": cannot read the " + what_ + ": " + why();
            return -1;
        }
        if (offset + size_t(r) > max_) {
            err = path_ + ": the " + what_ + " grew past the " + std::to_string(max_) + "-byte limit while being read";
            return -1;
        }
        return long(r);
    }
}

bool read_file(const std::string &path, size_t max_bytes, std::string &out, std::string &err, const char *what) {
    FileReader f;
    if (!f.open(path, max_bytes, err, what)) return false;
    std::string text;
    size_t got = 0;
    for (;;) {
        if (got == text.size()) text.resize(std::min(max_bytes + 1, std::max<size_t>(text.size() * 2, 65536)));
        const long n = f.pread(&text[got], text.size() - got, got, err);
        if (n < 0) return false;
        if (n == 0) break;
        got += size_t(n);
    }
    text.resize(got);
    out = std::move(text);
    return true;
}

bool file_id(const std::string &path, FileId &out) {
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) return false;
    out.dev = st.st_dev;
    out.ino = st.st_ino;
    return true;
}

AtomicFile::~AtomicFile() { abandon(); }

void AtomicFile::abandon() {
    if (fd_ >= 0) {
        ::close(fd_);
        ::unlink(tmp_.c_str());
        fd_ = -1;
    }
}

bool AtomicFile::open(const std::string &path, const std::vector<std::string> &protect, std::string &err) {
    abandon();
    if (path.empty()) {
        err = "output path is empty";
        return false;
    }
    struct stat st;
    mode_t mode = 0644;
    if (::stat(path.c_str(), &st) == 0) {
        if (!S_ISREG(st.st_mode)) {
            err = path + ": refusing to write over " + file_kind(st.st_mode) + " (outputs replace regular files only)";
            return false;
        }
        for (const auto &in : protect) {
            FileId id;
            if (!in.empty() && file_id(in, id) && id.dev == st.st_dev && id.ino == st.st_ino) {
                err = path + ": refusing to write over " + in + ", an input of this command (same file)";
                return false;
            }
        }
        mode = st.st_mode & 07777;
    } else if (errno != ENOENT) {
        err = path + ": cannot check the output: " + why();
        return false;
    }
    // mkstemp creates with O_EXCL: a link planted at the name is never followed.
    std::string tmpl = dir_of(path) + "/." + base_of(path) + ".XXXXXX";
    std::vector<char> buf(tmpl.begin(), tmpl.end());
    buf.push_back('\0');
    int fd = ::mkstemp(buf.data());
    if (fd < 0) {
        err = path + ": cannot create a temporary file in " + dir_of(path) + ": " + why();
        return false;
    }
    ::fchmod(fd, mode); // best effort: a 0600 temporary would still be written
    fd_ = fd;
    path_ = path;
    tmp_ = buf.data();
    return true;
}

bool AtomicFile::write(const char *data, size_t n, std::string &err) {
    if (fd_ < 0) {
        err = "internal: write to an output that is not open";
        return false;
    }
    while (n > 0) {
        ssize_t w = ::write(fd_, data, n);
        if (w < 0) {
            if (errno == EINTR) continue;
            err = path_ + ": cannot write: " + why();
            abandon();
            return false;
        }
        data += w;
        n -= size_t(w);
    }
    return true;
}

bool AtomicFile::commit(std::string &err) {
    if (fd_ < 0) {
        err = "internal: commit of an output that is not open";
        return false;
    }
    if (::fsync(fd_) != 0) {
        err = path_ + ": cannot sync the written data: " + why();
        abandon();
        return false;
    }
    if (::close(fd_) != 0) {
        fd_ = -1;
        err = path_ + ": cannot close the written file: " + why();
        ::unlink(tmp_.c_str());
        return false;
    }
    fd_ = -1;
    if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
        err = path_ + ": cannot replace the file: " + why();
        ::unlink(tmp_.c_str());
        return false;
    }
    return fsync_dir(dir_of(path_), err);
}

bool write_file_atomic(const std::string &path, const std::string &bytes, const std::vector<std::string> &protect,
                       std::string &err) {
    AtomicFile f;
    return f.open(path, protect, err) && f.write(bytes, err) && f.commit(err);
}

int write_fully(int fd, const void *data, size_t n) {
    const char *p = static_cast<const char *>(data);
    size_t done = 0;
    while (done < n) {
        const ssize_t w = ::write(fd, p + done, n - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return w < 0 ? errno : ENOSPC;
        done += size_t(w);
    }
    return 0;
}

bool sync_close(int &fd, const std::string &path, std::string &err) {
    bool ok = true;
    if (::fsync(fd) != 0) {
        err = path + ": fsync: " + std::strerror(errno);
        ok = false;
    }
    if (::close(fd) != 0 && ok) {
        err = path + ": close: " + std::strerror(errno);
        ok = false;
    }
    fd = -1;
    return ok;
}

} // namespace cdm::io

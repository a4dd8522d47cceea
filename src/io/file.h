// Whole-file input and output for every file libcdm reads or writes (device
// JSON, calibrations, datasets): one read with a size cap that refuses
// special files without blocking, one atomic write that never loses the old
// target nor clobbers an input or a non-regular file.
#pragma once

#include <cstddef>
#include <sys/types.h>

#include <string>
#include <vector>

namespace cdm::io {

// Caps, stated per use. A device description or a calibration is a few kB;
// 64 MiB is far beyond any real one yet bounds a hostile or mistaken input.
constexpr size_t kJsonMaxBytes = size_t(64) << 20;
// A dataset row is ~60 bytes: 1 GiB is ~17 million samples (days of
// recording at 200 Hz). Datasets are streamed (calib/dataset/dataset.h), so the cap
// bounds the work, not the memory.
constexpr size_t kDatasetMaxBytes = size_t(1) << 30;

// Reads a whole regular file. Opens with O_NONBLOCK and checks fstat before
// reading, so a FIFO without a writer, a device node (/dev/zero), a socket
// or a directory is refused at once with a message naming the path and what
// it is. Errors carry strerror(errno). `what` names the file's role in
// messages ("calibration", "device description", "dataset").
bool read_file(const std::string &path, size_t max_bytes, std::string &out, std::string &err,
               const char *what = "file");

// The same checks, for a reader that streams: open() refuses what
// read_file() refuses, with the same messages; pread() reads from any
// offset (several passes, concurrent readers), never past `max_bytes` (a
// file that grows beyond it while read is refused as read_file() refuses
// it). The descriptor stays open until destruction, so a file replaced by
// rename is still the one opened.
class FileReader {
public:
    FileReader() = default;
    ~FileReader();
    FileReader(const FileReader &) = delete;
    FileReader &operator=(const FileReader &) = delete;

    bool open(const std::string &path, size_t max_bytes, std::string &err, const char *what = "file");
    // Bytes read (0 at the end of the file), or -1 with err set.
    long pread(char *buf, size_t n, size_t offset, std::string &err) const;
    const std::string &path() const { return path_; }

private:
    int fd_ = -1;
    size_t max_ = 0;
    std::string path_, what_;
};

// "a directory", "a FIFO (named pipe)", ...: what a stat mode is, for
// messages that say why a path was refused.
const char *file_kind(mode_t m);

// Identity of an existing file (st_dev, st_ino), through symlinks.
struct FileId {
    unsigned long long dev = 0, ino = 0;
};
// False when `path` cannot be stat'ed (it does not exist, ...).
bool file_id(const std::string &path, FileId &out);

// Writes `bytes` to `path` atomically: an exclusive temporary (mkstemp) in
// the target's directory, write all, fsync, rename over the target, fsync
// the directory. Refuses a target that exists and is not a regular file
// (after following symlinks), and a target that is the same file as one of
// `protect_paths` (the command's own inputs). On failure the old target is
// untouched, no temporary is left, and `err` carries strerror(errno).
bool write_file_atomic(const std::string &path, const std::string &bytes,
                       const std::vector<std::string> &protect_paths, std::string &err);

// For the recorders' append-only files (the replay format, MCAP, the pose
// CSV), which keep whole records on a failure. write_fully: all n bytes at
// fd's position, retrying EINTR; 0, or the errno (a write that makes no
// progress is ENOSPC). sync_close: fsync, then close fd and set it to -1;
// false + err ("PATH: fsync: ...") on the first that fails.
int write_fully(int fd, const void *data, size_t n);
bool sync_close(int &fd, const std::string &path, std::string &err);

// The same, streaming: open() creates the temporary, write() appends,
// commit() fsyncs and renames; destruction without commit() removes the
// temporary. For writers that produce their output piece by piece.
class AtomicFile {
public:
    AtomicFile() = default;
    ~AtomicFile();
    AtomicFile(const AtomicFile &) = delete;
    AtomicFile &operator=(const AtomicFile &) = delete;

    bool open(const std::string &path, const std::vector<std::string> &protect_paths, std::string &err);
    bool write(const char *data, size_t n, std::string &err);
    bool write(const std::string &s, std::string &err) { return write(s.data(), s.size(), err); }
    bool commit(std::string &err);
    void abandon();
    bool is_open() const { return fd_ >= 0; }

private:
    int fd_ = -1;
    std::string path_, tmp_;
};

} // namespace cdm::io

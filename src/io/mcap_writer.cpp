// See mcap.h: the writer (chunked, indexed, CRC-checked; docs/recording.md).
#include "io/mcap.h"

#include "io/file.h"

#include <fcntl.h>
#include <lz4frame.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace cdm::mcap {

namespace {

// ------------------------------------------------------------ little endian

void put_u8(std::string &s, uint8_t v) { s.push_back(char(v)); }
void put_u16(std::string &s, uint16_t v) {
    for (int i = 0; i < 2; ++i) s.push_back(char(v >> (8 * i)));
}
void put_u32(std::string &s, uint32_t v) {
    for (int i = 0; i < 4; ++i) s.push_back(char(v >> (8 * i)));
}
void put_u64(std::string &s, uint64_t v) {
    for (int i = 0; i < 8; ++i) s.push_back(char(v >> (8 * i)));
}
void put_str(std::string &s, const std::string &v) {
    put_u32(s, uint32_t(v.size()));
    s += v;
}
void put_map(std::string &s, const StringMap &m) {
    std::string body;
    for (const auto &kv : m) {
        put_str(body, kv.first);
        put_str(body, kv.second);
    }
    put_u32(s, uint32_t(body.size()));
    s += body;
}
// opcode, u64 content length, content: the framing of every record.
std::string record(uint8_t op, const std::string &content) {
    std::string r;
    r.reserve(9 + content.size());
    put_u8(r, op);
    put_u64(r, content.size());
    r += content;
    return r;
}

uint32_t crc(const std::string &bytes, uint32_t previous = 0) {
    return uint32_t(::crc32_z(previous, reinterpret_cast<const Bytef *>(bytes.data()), bytes.size()));
}

// zstd's level 3 (its default) compresses a chunk of cdm's messages in a
// few milliseconds, well inside the half second the chunk spans.
constexpr int kZstdLevel = 3;

} // namespace

const char *compression_name(Compression c) {
    switch (c) {
    case Compression::Zstd: return "zstd";
    case Compression::Lz4: return "lz4";
    case Compression::None: break;
    }
    return "";
}

bool parse_compression(const std::string &name, Compression &out) {
    if (name == "zstd") out = Compression::Zstd;
    else if (name == "lz4") out = Compression::Lz4;
    else if (name == "none" || name.empty()) out = Compression::None;
    else return false;
    return true;
}

// ------------------------------------------------------------------ writer

void Writer::FreeZstd::operator()(void *p) const { ZSTD_freeCCtx(static_cast<ZSTD_CCtx *>(p)); }

Writer::~Writer() {
    if (fd_ >= 0) ::close(fd_);
}

bool Writer::emit(const std::string &bytes, std::string &err) {
    if (failed_) {
        err = fail_text_;
        return false;
    }
    if (const int e = io::write_fully(fd_, bytes.data(), bytes.size())) {
        // Drop the partial piece: the file stays a run of whole records,
        // which the reader plays (it reports the missing footer).
        const bool cut = ::ftruncate(fd_, off_t(offset_)) == 0 && ::lseek(fd_, off_t(offset_), SEEK_SET) >= 0;
        failed_ = true;
        fail_text_ = path_ + ": write error after " + std::to_string(message_count_) + " messages (" +
                     std::to_string(offset_) + " bytes kept" + (cut ? "" : ", the last chunk may be partial") +
                     "): " + std::strerror(e);
        err = fail_text_;
        return false;
    }
    offset_ += bytes.size();
    return true;
}

bool Writer::open(const std::string &path, const std::string &profile, const std::string &library,
                  std::string &err, Compression compression) {
    if (fd_ >= 0) {
        err = path_ + ": writer already open";
        return false;
    }
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY, 0644);
    if (fd_ < 0) {
        err = path + ": cannot create: " + std::strerror(errno) +
              (errno == EEXIST ? " (not writing over an existing file)" : "");
        return false;
    }
    path_ = path;
    compression_ = compression;
    std::string h(reinterpret_cast<const char *>(kMagic), sizeof kMagic);
    std::string c;
    put_str(c, profile);
    put_str(c, library);
    h += record(kHeader, c);
    if (!emit(h, err)) return false;
    data_crc_ = crc(h);
    return true;
}

uint16_t Writer::add_schema(const std::string &name, const std::string &encoding, const std::string &data) {
    const uint16_t id = uint16_t(schemas_.size() + 1);
    std::string c;
    put_u16(c, id);
    put_str(c, name);
    put_str(c, encoding);
    put_u32(c, uint32_t(data.size())); // Schema data is u32-length-prefixed
    c += data;
    schemas_.push_back({id, record(kSchema, c)});
    pending_ += schemas_.back().record;
    return id;
}

uint16_t Writer::add_channel(uint16_t schema_id, const std::string &topic, const std::string &message_encoding,
                             const StringMap &metadata) {
    const uint16_t id = uint16_t(channels_.size() + 1);
    std::string c;
    put_u16(c, id);
    put_u16(c, schema_id);
    put_str(c, topic);
    put_str(c, message_encoding);
    put_map(c, metadata);
    channels_.push_back({id, record(kChannel, c)});
    pending_ += channels_.back().record;
    return id;
}

bool Writer::add_metadata(const std::string &name, const StringMap &entries, std::string &err) {
    std::string c;
    put_str(c, name);
    put_map(c, entries);
    const std::string meta = record(kMetadata, c);
    const uint64_t at = offset_ + pending_.size();
    const std::string out = pending_ + meta;
    if (!emit(out, err)) return false;
    data_crc_ = crc(out, data_crc_);
    pending_.clear();
    metadata_.emplace_back(at, name);
    metadata_lengths_.push_back(meta.size());
    return true;
}

bool Writer::write_message(uint16_t channel, uint64_t log_time, const uint8_t *data, size_t len, std::string &err) {
    if (fd_ < 0 || failed_) {
        err = failed_ ? fail_text_ : std::string("MCAP writer not open");
        return false;
    }
    if (channel == 0 || channel > channels_.size()) {
        err = path_ + ": message on undeclared channel " + std::to_string(channel);
        return false;
    }
    std::string c;
    c.reserve(22 + len);
    put_u16(c, channel);
    put_u32(c, sequence_[channel]++);
    put_u64(c, log_time);
    put_u64(c, log_time); // publish time: not known apart from the log time
    c.append(reinterpret_cast<const char *>(data), len);
    if (chunk_.empty()) chunk_t0_ = chunk_t1_ = log_time;
    chunk_t0_ = std::min(chunk_t0_, log_time);
    chunk_t1_ = std::max(chunk_t1_, log_time);
    chunk_index_[channel].emplace_back(log_time, chunk_.size());
    chunk_ += record(kMessage, c);
    if (message_count_ == 0) t_first_ = t_last_ = log_time;
    t_first_ = std::min(t_first_, log_time);
    t_last_ = std::max(t_last_, log_time);
    ++message_count_;
    ++per_channel_[channel];
    return chunk_.size() < kChunkBytes || flush_chunk(err);
}

bool Writer::flush_chunk(std::string &err) {
    if (chunk_.empty() && pending_.empty()) return true;
    std::string out = pending_;
    pending_.clear();
    if (chunk_.empty()) {
        if (!emit(out, err)) return false;
        data_crc_ = crc(out, data_crc_);
        return true;
    }
    ChunkInfo ci{};
    ci.start = offset_ + out.size();
    ci.t0 = chunk_t0_;
    ci.t1 = chunk_t1_;
    ci.size = chunk_.size();
    std::string records;
    if (!compress_chunk(records, err)) return false;
    ci.compressed_size = records.size();
    std::string c;
    put_u64(c, chunk_t0_);
    put_u64(c, chunk_t1_);
    put_u64(c, chunk_.size());
    put_u32(c, crc(chunk_)); // of the uncompressed records
    put_str(c, compression_name(compression_));
    put_u64(c, records.size());
    c += records;
    const std::string chunk_record = record(kChunk, c);
    ci.length = chunk_record.size();
    out += chunk_record;
    uint64_t at = ci.start + ci.length;
    for (const auto &ch : chunk_index_) {
        std::string m;
        put_u16(m, ch.first);
        put_u32(m, uint32_t(ch.second.size() * 16));
        for (const auto &e : ch.second) {
            put_u64(m, e.first);
            put_u64(m, e.second);
        }
        const std::string r = record(kMessageIndex, m);
        ci.index_offsets[ch.first] = at;
        at += r.size();
        out += r;
    }
    ci.index_length = at - ci.start - ci.length;
    if (!emit(out, err)) return false;
    data_crc_ = crc(out, data_crc_);
    chunks_.push_back(std::move(ci));
    chunk_.clear();
    chunk_index_.clear();
    return true;
}

bool Writer::compress_chunk(std::string &out, std::string &err) {
    const auto fail = [&](const std::string &what) {
        failed_ = true;
        fail_text_ = path_ + ": cannot compress a chunk of " + std::to_string(chunk_.size()) + " bytes with " +
                     compression_name(compression_) + ": " + what;
        err = fail_text_;
        return false;
    };
    if (compression_ == Compression::None) {
        out = chunk_;
        return true;
    }
    if (compression_ == Compression::Zstd) {
        if (!zstd_) zstd_.reset(ZSTD_createCCtx());
        if (!zstd_) return fail("out of memory");
        out.resize(ZSTD_compressBound(chunk_.size()));
        const size_t n = ZSTD_compressCCtx(static_cast<ZSTD_CCtx *>(zstd_.get()), out.data(), out.size(),
                                           chunk_.data(), chunk_.size(), kZstdLevel);
        if (ZSTD_isError(n)) return fail(ZSTD_getErrorName(n));
        out.resize(n);
        return true;
    }
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.contentSize = chunk_.size(); // lets a reader size its buffer from the frame too
    out.resize(LZ4F_compressFrameBound(chunk_.size(), &prefs));
    const size_t n = LZ4F_compressFrame(out.data(), out.size(), chunk_.data(), chunk_.size(), &prefs);
    if (LZ4F_isError(n)) return fail(LZ4F_getErrorName(n));
    out.resize(n);
    return true;
}

bool Writer::close(std::string &err) {
    if (fd_ < 0) return true;
    bool ok = !failed_ && flush_chunk(err);
    if (ok) {
        std::string c;
        put_u32(c, data_crc_);
        std::string tail = record(kDataEnd, c);
        const uint64_t summary_start = offset_ + tail.size();
        // The summary: each group's position goes into a SummaryOffset.
        std::string summary, offsets;
        auto group = [&](uint8_t op, const std::string &bytes) {
            if (bytes.empty()) return;
            std::string o;
            put_u8(o, op);
            put_u64(o, summary_start + summary.size());
            put_u64(o, bytes.size());
            offsets += record(kSummaryOffset, o);
            summary += bytes;
        };
        std::string g;
        for (const auto &s : schemas_) g += s.record;
        group(kSchema, g);
        g.clear();
        for (const auto &ch : channels_) g += ch.record;
        group(kChannel, g);
        std::string st;
        put_u64(st, message_count_);
        put_u16(st, uint16_t(schemas_.size()));
        put_u32(st, uint32_t(channels_.size()));
        put_u32(st, 0); // attachments
        put_u32(st, uint32_t(metadata_.size()));
        put_u32(st, uint32_t(chunks_.size()));
        put_u64(st, t_first_);
        put_u64(st, t_last_);
        put_u32(st, uint32_t(per_channel_.size() * 10));
        for (const auto &pc : per_channel_) {
            put_u16(st, pc.first);
            put_u64(st, pc.second);
        }
        group(kStatistics, record(kStatistics, st));
        g.clear();
        for (const auto &ci : chunks_) {
            std::string r;
            put_u64(r, ci.t0);
            put_u64(r, ci.t1);
            put_u64(r, ci.start);
            put_u64(r, ci.length);
            put_u32(r, uint32_t(ci.index_offsets.size() * 10));
            for (const auto &io : ci.index_offsets) {
                put_u16(r, io.first);
                put_u64(r, io.second);
            }
            put_u64(r, ci.index_length);
            put_str(r, compression_name(compression_));
            put_u64(r, ci.compressed_size);
            put_u64(r, ci.size);
            g += record(kChunkIndex, r);
        }
        group(kChunkIndex, g);
        g.clear();
        for (size_t i = 0; i < metadata_.size(); ++i) {
            std::string r;
            put_u64(r, metadata_[i].first);
            put_u64(r, metadata_lengths_[i]);
            put_str(r, metadata_[i].second);
            g += record(kMetadataIndex, r);
        }
        group(kMetadataIndex, g);
        const uint64_t offsets_start = summary_start + summary.size();
        std::string footer;
        put_u8(footer, kFooter);
        put_u64(footer, 20);
        put_u64(footer, summary_start);
        put_u64(footer, offsets_start);
        // CRC from the summary's first byte through summary_offset_start.
        std::string covered = summary + offsets + footer;
        put_u32(footer, crc(covered));
        tail += summary + offsets + footer;
        tail.append(reinterpret_cast<const char *>(kMagic), sizeof kMagic);
        ok = emit(tail, err);
    } else if (err.empty()) {
        err = fail_text_;
    }
    std::string close_err;
    if (!io::sync_close(fd_, path_, close_err) && ok) {
        err = close_err;
        ok = false;
    }
    return ok;
}

} // namespace cdm::mcap

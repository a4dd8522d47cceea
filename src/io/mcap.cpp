#include "io/mcap.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
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

const std::array<uint32_t, 256> &crc_table() {
    static const std::array<uint32_t, 256> t = [] {
        std::array<uint32_t, 256> a{};
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
            a[i] = c;
        }
        return a;
    }();
    return t;
}

} // namespace

uint32_t crc32(const uint8_t *data, size_t len, uint32_t crc) {
    const auto &t = crc_table();
    crc = ~crc;
    for (size_t i = 0; i < len; ++i) crc = t[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
    return ~crc;
}

// ------------------------------------------------------------------ writer

Writer::~Writer() {
    if (fd_ >= 0) ::close(fd_);
}

bool Writer::emit(const std::string &bytes, std::string &err) {
    if (failed_) {
        err = fail_text_;
        return false;
    }
    size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t w = ::write(fd_, bytes.data() + done, bytes.size() - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            const int e = w < 0 ? errno : ENOSPC;
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
        done += size_t(w);
    }
    offset_ += bytes.size();
    return true;
}

bool Writer::open(const std::string &path, const std::string &profile, const std::string &library,
                  std::string &err) {
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
    std::string h(reinterpret_cast<const char *>(kMagic), sizeof kMagic);
    std::string c;
    put_str(c, profile);
    put_str(c, library);
    h += record(kHeader, c);
    if (!emit(h, err)) return false;
    data_crc_ = crc32(reinterpret_cast<const uint8_t *>(h.data()), h.size());
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
    data_crc_ = crc32(reinterpret_cast<const uint8_t *>(out.data()), out.size(), data_crc_);
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
        data_crc_ = crc32(reinterpret_cast<const uint8_t *>(out.data()), out.size(), data_crc_);
        return true;
    }
    ChunkInfo ci{};
    ci.start = offset_ + out.size();
    ci.t0 = chunk_t0_;
    ci.t1 = chunk_t1_;
    ci.size = chunk_.size();
    std::string c;
    put_u64(c, chunk_t0_);
    put_u64(c, chunk_t1_);
    put_u64(c, chunk_.size());
    put_u32(c, crc32(reinterpret_cast<const uint8_t *>(chunk_.data()), chunk_.size()));
    put_str(c, ""); // no compression: message bytes stay where replay can point at them
    put_u64(c, chunk_.size());
    c += chunk_;
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
    data_crc_ = crc32(reinterpret_cast<const uint8_t *>(out.data()), out.size(), data_crc_);
    chunks_.push_back(std::move(ci));
    chunk_.clear();
    chunk_index_.clear();
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
            put_str(r, "");
            put_u64(r, ci.size); // compressed size = uncompressed size
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
        put_u32(footer, crc32(reinterpret_cast<const uint8_t *>(covered.data()), covered.size()));
        tail += summary + offsets + footer;
        tail.append(reinterpret_cast<const char *>(kMagic), sizeof kMagic);
        ok = emit(tail, err);
    } else if (err.empty()) {
        err = fail_text_;
    }
    if (::fsync(fd_) != 0 && ok) {
        err = path_ + ": fsync: " + std::strerror(errno);
        ok = false;
    }
    if (::close(fd_) != 0 && ok) {
        err = path_ + ": close: " + std::strerror(errno);
        ok = false;
    }
    fd_ = -1;
    return ok;
}

// ------------------------------------------------------------------ reader

namespace {

// A bounded view of [begin, end) of the file; every read checks what is
// left first, and a failure names the absolute offset.
struct Cursor {
    const uint8_t *base;
    size_t pos, end;
    const std::string &name;
    std::string &err;

    bool fail(size_t at, const std::string &what) {
        err = name + ": byte " + std::to_string(at) + ": " + what;
        return false;
    }
    size_t left() const { return end - pos; }
    bool need(size_t n, const char *what) {
        if (left() >= n) return true;
        return fail(pos, std::string(what) + " runs past the end of its record (" + std::to_string(n) +
                             " bytes needed, " + std::to_string(left()) + " left)");
    }
    uint64_t le(size_t n) {
        uint64_t v = 0;
        for (size_t i = 0; i < n; ++i) v |= uint64_t(base[pos + i]) << (8 * i);
        pos += n;
        return v;
    }
    bool u16(uint16_t &v, const char *what) { return need(2, what) && (v = uint16_t(le(2)), true); }
    bool u32(uint32_t &v, const char *what) { return need(4, what) && (v = uint32_t(le(4)), true); }
    bool u64(uint64_t &v, const char *what) { return need(8, what) && (v = le(8), true); }
    bool str(std::string &s, const char *what) {
        uint32_t n = 0;
        if (!u32(n, what) || !need(n, what)) return false;
        s.assign(reinterpret_cast<const char *>(base + pos), n);
        pos += n;
        return true;
    }
    bool map(StringMap &m, const char *what) {
        uint32_t n = 0;
        if (!u32(n, what) || !need(n, what)) return false;
        Cursor in{base, pos, pos + n, name, err};
        while (in.left() > 0) {
            std::string k, v;
            if (!in.str(k, what) || !in.str(v, what)) return false;
            m.emplace_back(std::move(k), std::move(v));
        }
        pos += n;
        return true;
    }
};

const char *op_name(uint8_t op) {
    switch (op) {
    case kHeader: return "Header";
    case kFooter: return "Footer";
    case kSchema: return "Schema";
    case kChannel: return "Channel";
    case kMessage: return "Message";
    case kChunk: return "Chunk";
    case kMessageIndex: return "MessageIndex";
    case kChunkIndex: return "ChunkIndex";
    case kAttachment: return "Attachment";
    case kAttachmentIndex: return "AttachmentIndex";
    case kStatistics: return "Statistics";
    case kMetadata: return "Metadata";
    case kMetadataIndex: return "MetadataIndex";
    case kSummaryOffset: return "SummaryOffset";
    case kDataEnd: return "DataEnd";
    default: return "unknown";
    }
}

struct Parser {
    const uint8_t *data;
    size_t size;
    const std::string &name;
    std::string &err;
    File &f;

    bool fail(size_t at, const std::string &what) {
        err = name + ": byte " + std::to_string(at) + ": " + what;
        return false;
    }

    bool schema(Cursor c, size_t at) {
        Schema s;
        uint32_t n = 0;
        if (!c.u16(s.id, "Schema id") || !c.str(s.name, "Schema name") || !c.str(s.encoding, "Schema encoding") ||
            !c.u32(n, "Schema data") || !c.need(n, "Schema data"))
            return false;
        s.data.assign(reinterpret_cast<const char *>(c.base + c.pos), n);
        if (s.id == 0) return true; // invalid by the specification: ignored
        auto it = f.schemas.find(s.id);
        if (it != f.schemas.end() && (it->second.name != s.name || it->second.encoding != s.encoding ||
                                      it->second.data != s.data))
            return fail(at, "schema " + std::to_string(s.id) + " redefined differently");
        f.schemas[s.id] = std::move(s);
        return true;
    }

    bool channel(Cursor c, size_t at) {
        Channel ch;
        if (!c.u16(ch.id, "Channel id") || !c.u16(ch.schema_id, "Channel schema id") ||
            !c.str(ch.topic, "Channel topic") || !c.str(ch.message_encoding, "Channel message encoding") ||
            !c.map(ch.metadata, "Channel metadata"))
            return false;
        if (ch.schema_id != 0 && !f.schemas.count(ch.schema_id))
            return fail(at, "channel " + std::to_string(ch.id) + " (" + ch.topic + ") refers to schema " +
                                std::to_string(ch.schema_id) + ", not declared before it");
        auto it = f.channels.find(ch.id);
        if (it != f.channels.end() && (it->second.topic != ch.topic || it->second.schema_id != ch.schema_id ||
                                       it->second.message_encoding != ch.message_encoding))
            return fail(at, "channel " + std::to_string(ch.id) + " redefined differently");
        f.channels[ch.id] = std::move(ch);
        return true;
    }

    bool message(Cursor c, size_t at) {
        Message m;
        if (!c.u16(m.channel, "Message channel id") || !c.u32(m.sequence, "Message sequence") ||
            !c.u64(m.log_time, "Message log time") || !c.u64(m.publish_time, "Message publish time"))
            return false;
        if (!f.channels.count(m.channel))
            return fail(at, "message on channel " + std::to_string(m.channel) + ", not declared before it");
        if (f.messages.size() >= kMaxMessages)
            return fail(at, "more than " + std::to_string(kMaxMessages) + " messages");
        m.offset = c.pos;
        m.length = c.left();
        f.messages.push_back(m);
        return true;
    }

    bool metadata(Cursor c) {
        Metadata m;
        if (!c.str(m.name, "Metadata name") || !c.map(m.entries, "Metadata entries")) return false;
        f.metadata.push_back(std::move(m));
        return true;
    }

    bool chunk(Cursor c, size_t at) {
        uint64_t t0, t1, usize, csize;
        uint32_t crc;
        std::string compression;
        if (!c.u64(t0, "Chunk start time") || !c.u64(t1, "Chunk end time") ||
            !c.u64(usize, "Chunk uncompressed size") || !c.u32(crc, "Chunk CRC") ||
            !c.str(compression, "Chunk compression") || !c.u64(csize, "Chunk records length"))
            return false;
        if (!compression.empty())
            return fail(at, "chunk compressed with \"" + compression.substr(0, 32) +
                                "\": this reader takes uncompressed chunks (cdm writes them; `mcap convert "
                                "--compression none` makes them)");
        if (csize > c.left())
            return fail(c.pos - 8, "chunk records length " + std::to_string(csize) + " runs past the chunk (" +
                                       std::to_string(c.left()) + " bytes left)");
        if (csize != usize)
            return fail(at, "uncompressed chunk of " + std::to_string(csize) + " bytes announces " +
                                std::to_string(usize) + " uncompressed");
        const size_t begin = c.pos, end = c.pos + size_t(csize);
        if (crc != 0 && crc32(data + begin, end - begin) != crc) return fail(at, "chunk CRC mismatch");
        size_t pos = begin;
        while (pos < end) {
            if (end - pos < 9) return fail(pos, "record header runs past the end of its chunk");
            const uint8_t op = data[pos];
            Cursor h{data, pos + 1, end, name, err};
            const uint64_t len = h.le(8);
            if (len > end - pos - 9)
                return fail(pos, std::string(op_name(op)) + " record of " + std::to_string(len) +
                                     " bytes runs past the end of its chunk");
            Cursor rc{data, pos + 9, pos + 9 + size_t(len), name, err};
            bool ok = true;
            if (op == kSchema) ok = schema(rc, pos);
            else if (op == kChannel) ok = channel(rc, pos);
            else if (op == kMessage) ok = message(rc, pos);
            // Anything else in a chunk is not for a chunk; skipped like an unknown record.
            if (!ok) return false;
            pos += 9 + size_t(len);
        }
        return true;
    }

    void truncated(size_t at, const std::string &where) {
        f.truncated_bytes = size - at;
        f.warning = name + ": byte " + std::to_string(at) + ": recording ends " + where + "; " +
                    std::to_string(size - at) + " trailing bytes dropped, " + std::to_string(f.messages.size()) +
                    " complete messages kept (was the recorder killed, or the disk full?)";
    }

    bool run() {
        if (size < sizeof kMagic || std::memcmp(data, kMagic, sizeof kMagic) != 0) {
            if (size >= 6 && std::memcmp(data + 1, "MCAP", 4) == 0 && data[0] == 0x89)
                return fail(5, "MCAP major version '" + std::string(1, char(data[5])) + "', this reader takes '0'");
            return fail(0, "not an MCAP file (magic \\x89MCAP0\\r\\n missing)");
        }
        size_t pos = sizeof kMagic;
        bool header = false, data_end = false;
        while (true) {
            if (size - pos < 9) {
                if (!header) return fail(pos, "file ends before its Header record");
                truncated(pos, pos == size ? "without its footer" : "inside a record header");
                return true;
            }
            const uint8_t op = data[pos];
            Cursor h{data, pos + 1, size, name, err};
            const uint64_t len = h.le(8);
            if (len > size - pos - 9) {
                if (!header) return fail(pos, "file ends inside its Header record");
                truncated(pos, std::string("inside a ") + op_name(op) + " record (" + std::to_string(len) +
                                   " bytes announced, " + std::to_string(size - pos - 9) + " there)");
                return true;
            }
            Cursor c{data, pos + 9, pos + 9 + size_t(len), name, err};
            if (!header) {
                if (op != kHeader)
                    return fail(pos, std::string("first record is ") + op_name(op) + " (opcode " +
                                         std::to_string(op) + "), not the Header");
                if (!c.str(f.profile, "Header profile") || !c.str(f.library, "Header library")) return false;
                header = true;
            } else if (op == kFooter) {
                const size_t after = pos + 9 + size_t(len);
                if (size - after != sizeof kMagic || std::memcmp(data + after, kMagic, sizeof kMagic) != 0)
                    return fail(after, "the Footer is not followed by the closing magic and the end of the file");
                f.complete = true;
                return true;
            } else if (!data_end) {
                bool ok = true;
                if (op == kSchema) ok = schema(c, pos);
                else if (op == kChannel) ok = channel(c, pos);
                else if (op == kMessage) ok = message(c, pos);
                else if (op == kChunk) ok = chunk(c, pos);
                else if (op == kMetadata) ok = metadata(c);
                else if (op == kHeader) return fail(pos, "a second Header record");
                else if (op == kDataEnd) data_end = true;
                if (!ok) return false;
            }
            // After DataEnd: the summary repeats what the data section held;
            // its records are framed above and otherwise skipped.
            pos += 9 + size_t(len);
        }
    }
};

} // namespace

bool parse(const uint8_t *data, size_t size, const std::string &name, File &out, std::string &err) {
    File f;
    Parser p{data, size, name, err, f};
    if (!p.run()) return false;
    out = std::move(f);
    return true;
}

} // namespace cdm::mcap

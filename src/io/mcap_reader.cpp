// See mcap.h: the reader (a bounded parse of a whole file; every length
// checked before it is read, errors name the byte offset).
#include "io/mcap.h"

#include <fcntl.h>
#include <lz4frame.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <memory>
#include <new>

namespace cdm::mcap {

// ------------------------------------------------------------------ reader

namespace {

// A bounded view of [begin, end) of the file; every read checks what is
// left first, and a failure names the absolute offset.
struct Cursor {
    const uint8_t *base;
    size_t pos, end;
    const std::string &name;
    std::string &err;
    // A decompressed chunk's records: errors name the Chunk record's byte in
    // the file, and the offset in the decompressed records after it.
    size_t packed_at = std::string::npos;

    bool fail(size_t at, const std::string &what) {
        if (packed_at == std::string::npos) err = name + ": byte " + std::to_string(at) + ": " + what;
        else
            err = name + ": byte " + std::to_string(packed_at) + ": " + what + " (byte " + std::to_string(at) +
                  " of the chunk's decompressed records)";
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
        Cursor in{base, pos, pos + n, name, err, packed_at};
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
    uint64_t unpacked_ = 0; // decompressed bytes so far

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

    bool message(Cursor c, size_t at, bool packed = false) {
        Message m;
        if (!c.u16(m.channel, "Message channel id") || !c.u32(m.sequence, "Message sequence") ||
            !c.u64(m.log_time, "Message log time") || !c.u64(m.publish_time, "Message publish time"))
            return false;
        if (!f.channels.count(m.channel))
            return fail(at, "message on channel " + std::to_string(m.channel) + ", not declared before it");
        if (f.messages.size() >= kMaxMessages)
            return fail(at, "more than " + std::to_string(kMaxMessages) + " messages");
        m.data = c.base + c.pos;
        m.length = c.left();
        m.offset = packed ? at : c.pos;
        f.messages.push_back(m);
        return true;
    }

    bool metadata(Cursor c) {
        Metadata m;
        if (!c.str(m.name, "Metadata name") || !c.map(m.entries, "Metadata entries")) return false;
        f.metadata.push_back(std::move(m));
        return true;
    }

    // Decompresses `csize` bytes at `src` into exactly `usize` bytes of `out`.
    bool decompress(const std::string &compression, const uint8_t *src, size_t csize, uint8_t *out, size_t usize,
                    size_t at) {
        if (compression == "zstd") {
            const size_t n = ZSTD_decompress(out, usize, src, csize);
            if (ZSTD_isError(n))
                return fail(at, std::string("zstd chunk does not decompress into the ") + std::to_string(usize) +
                                    " bytes it announces: " + ZSTD_getErrorName(n));
            if (n != usize)
                return fail(at, "zstd chunk decompresses to " + std::to_string(n) + " bytes, not the " +
                                    std::to_string(usize) + " it announces");
            return true;
        }
        LZ4F_dctx *d = nullptr;
        if (LZ4F_isError(LZ4F_createDecompressionContext(&d, LZ4F_VERSION))) return fail(at, "lz4: out of memory");
        std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> owned(d, LZ4F_freeDecompressionContext);
        size_t in = 0, done = 0, hint = 1;
        while (in < csize) {
            size_t dn = usize - done, sn = csize - in;
            hint = LZ4F_decompress(d, out + done, &dn, src + in, &sn, nullptr);
            if (LZ4F_isError(hint))
                return fail(at, std::string("lz4 chunk does not decompress: ") + LZ4F_getErrorName(hint));
            in += sn;
            done += dn;
            if (sn == 0 && dn == 0)
                return fail(at, "lz4 chunk decompresses to more than the " + std::to_string(usize) +
                                    " bytes it announces");
        }
        if (hint != 0) return fail(at, "lz4 chunk ends inside its frame");
        if (done != usize)
            return fail(at, "lz4 chunk decompresses to " + std::to_string(done) + " bytes, not the " +
                                std::to_string(usize) + " it announces");
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
        if (!compression.empty() && compression != "zstd" && compression != "lz4")
            return fail(at, "chunk compressed with \"" + compression.substr(0, 32) +
                                "\": this reader takes zstd, lz4 and uncompressed chunks");
        if (csize > c.left())
            return fail(c.pos - 8, "chunk records length " + std::to_string(csize) + " runs past the chunk (" +
                                       std::to_string(c.left()) + " bytes left)");
        const uint8_t *records = data;
        size_t base = c.pos, end = c.pos + size_t(csize);
        if (compression.empty()) {
            if (csize != usize)
                return fail(at, "uncompressed chunk of " + std::to_string(csize) + " bytes announces " +
                                    std::to_string(usize) + " uncompressed");
        } else {
            if (usize > kMaxUncompressedBytes - unpacked_)
                return fail(at, "chunk announces " + std::to_string(usize) + " bytes uncompressed, past the " +
                                    std::to_string(kMaxUncompressedBytes) + " bytes a recording may hold");
            // No format makes more than this from so few bytes: zstd's
            // smallest block (RLE, 4 bytes) stands for at most 128 KiB, an
            // LZ4 sequence's length byte for at most 255 bytes.
            const uint64_t ratio = compression == "zstd" ? 32768 : 256;
            if (usize / ratio > csize)
                return fail(at, "chunk announces " + std::to_string(usize) + " bytes uncompressed from " +
                                    std::to_string(csize) + " " + compression + " bytes, more than " +
                                    compression + " can make (" + std::to_string(ratio) + " to 1)");
            // A zstd frame that states its size must state the chunk's.
            const unsigned long long framed = compression == "zstd" ? ZSTD_getFrameContentSize(data + c.pos, csize)
                                                                    : ZSTD_CONTENTSIZE_UNKNOWN;
            if (framed != ZSTD_CONTENTSIZE_UNKNOWN && framed != usize)
                return fail(at, "zstd chunk announces " + std::to_string(usize) + " bytes uncompressed, its frame " +
                                    (framed == ZSTD_CONTENTSIZE_ERROR ? std::string("is not a zstd frame")
                                                                      : std::to_string(framed)));
            unpacked_ += usize;
            std::unique_ptr<uint8_t[]> out(new (std::nothrow) uint8_t[size_t(usize) + 1]); // +1: never empty
            if (!out) return fail(at, "no memory for a chunk of " + std::to_string(usize) + " bytes uncompressed");
            if (!decompress(compression, data + c.pos, size_t(csize), out.get(), size_t(usize), at)) return false;
            f.chunk_data.push_back({std::move(out), size_t(usize)});
            records = f.chunk_data.back().bytes.get();
            base = 0;
            end = size_t(usize);
        }
        if (crc != 0 && uint32_t(::crc32_z(0, records + base, end - base)) != crc)
            return fail(at, "chunk CRC mismatch");
        return chunk_records(records, base, end, compression.empty() ? std::string::npos : at);
    }

    // The records of one chunk, [begin, end) of `buf` (the file's bytes, or a
    // decompressed chunk whose errors point at the chunk's byte `packed_at`).
    bool chunk_records(const uint8_t *buf, size_t begin, size_t end, size_t packed_at) {
        const auto where = [&](size_t p) { return packed_at == std::string::npos ? p : packed_at; };
        size_t pos = begin;
        while (pos < end) {
            Cursor h{buf, pos + 1, end, name, err, packed_at};
            if (end - pos < 9) return h.fail(pos, "record header runs past the end of its chunk");
            const uint8_t op = buf[pos];
            const uint64_t len = h.le(8);
            if (len > end - pos - 9)
                return h.fail(pos, std::string(op_name(op)) + " record of " + std::to_string(len) +
                                       " bytes runs past the end of its chunk");
            Cursor rc{buf, pos + 9, pos + 9 + size_t(len), name, err, packed_at};
            bool ok = true;
            if (op == kSchema) ok = schema(rc, where(pos));
            else if (op == kChannel) ok = channel(rc, where(pos));
            else if (op == kMessage) ok = message(rc, where(pos), packed_at != std::string::npos);
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

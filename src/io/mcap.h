// MCAP (https://mcap.dev/spec), the container of ROS 2 bags and Foxglove:
// a writer and a reader of the container itself, written from the
// specification. What goes in it (cdm's channels, schemas and encodings)
// is src/device/recording/recording_mcap.*; docs/recording.md describes both.
//
// The writer puts messages in chunks (compressed with zstd by default, lz4
// or none on request), each followed by its message indexes, and ends the
// file with a summary (schemas, channels, statistics, chunk and metadata
// indexes, summary offsets) so that readers seek instead of scanning. It
// writes each chunk with its indexes in one write(2), so a process killed
// mid-recording leaves every chunk written before it (the reader below
// keeps them and says what was lost).
//
// The reader takes the whole file in memory and checks every length
// against what is left before it reads: hostile input is refused with
// "NAME: byte OFFSET: what", never read out of bounds. Decompression is
// bounded by the size a chunk announces, which is itself capped.
//
// CRCs are zlib's crc32 (ISO-HDLC), the checksum MCAP's CRC fields use.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace cdm::mcap {

constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

// Record opcodes (the specification's "Records").
enum Op : uint8_t {
    kHeader = 0x01,
    kFooter = 0x02,
    kSchema = 0x03,
    kChannel = 0x04,
    kMessage = 0x05,
    kChunk = 0x06,
    kMessageIndex = 0x07,
    kChunkIndex = 0x08,
    kAttachment = 0x09,
    kAttachmentIndex = 0x0A,
    kStatistics = 0x0B,
    kMetadata = 0x0C,
    kMetadataIndex = 0x0D,
    kSummaryOffset = 0x0E,
    kDataEnd = 0x0F,
};

// A chunk's compression, by its name in the Chunk record: "" (none),
// "zstd", "lz4" (an LZ4 frame).
enum class Compression { None, Zstd, Lz4 };
const char *compression_name(Compression c);
// "none" (or ""), "zstd", "lz4"; false for anything else.
bool parse_compression(const std::string &name, Compression &out);

using StringMap = std::vector<std::pair<std::string, std::string>>;

// Writes one MCAP file. Not thread-safe (the caller serialises).
class Writer {
public:
    // A chunk is written when its records pass this size: about half a
    // second of cdm's three channels at 1 kHz, so a kill loses at most that.
    static constexpr size_t kChunkBytes = 128 * 1024;

    Writer() = default;
    ~Writer(); // closes without a summary: the file stays as written so far
    Writer(const Writer &) = delete;
    Writer &operator=(const Writer &) = delete;

    // Creates `path` (a new file only: O_EXCL, never through a symlink) and
    // writes the magic and the Header record. Chunks are compressed with
    // `compression`.
    bool open(const std::string &path, const std::string &profile, const std::string &library, std::string &err,
              Compression compression = Compression::Zstd);
    // Before the first message: declarations (ids from 1) and Metadata.
    uint16_t add_schema(const std::string &name, const std::string &encoding, const std::string &data);
    uint16_t add_channel(uint16_t schema_id, const std::string &topic, const std::string &message_encoding,
                         const StringMap &metadata = {});
    bool add_metadata(const std::string &name, const StringMap &entries, std::string &err);
    // Log times must not decrease within a channel (readers index by them);
    // publish time = log time.
    bool write_message(uint16_t channel, uint64_t log_time, const uint8_t *data, size_t len, std::string &err);
    // Flushes the last chunk, writes DataEnd, the summary, the footer and
    // the closing magic, fsyncs and closes. After a write error the file
    // is kept as far as it was complete and the error is returned.
    bool close(std::string &err);

    uint64_t messages() const { return message_count_; }
    bool is_open() const { return fd_ >= 0; }

private:
    struct ChunkInfo {
        uint64_t start, length, index_length, t0, t1;
        std::map<uint16_t, uint64_t> index_offsets; // channel -> MessageIndex offset in the file
        uint64_t size, compressed_size;
    };
    struct Declared {
        uint16_t id;
        std::string record; // the Schema or Channel record, opcode and length included
    };
    bool flush_chunk(std::string &err);
    // The open chunk's records compressed (or copied) into `out`.
    bool compress_chunk(std::string &out, std::string &err);
    bool emit(const std::string &bytes, std::string &err); // one write(2) loop, CRC, truncation on failure
    int fd_ = -1;
    bool failed_ = false;
    Compression compression_ = Compression::Zstd;
    struct FreeZstd {
        void operator()(void *p) const;
    };
    std::unique_ptr<void, FreeZstd> zstd_; // ZSTD_CCtx, reused from chunk to chunk
    std::string path_, fail_text_;
    uint64_t offset_ = 0;   // bytes in the file
    uint32_t data_crc_ = 0; // over every byte written before DataEnd
    std::vector<Declared> schemas_, channels_;
    std::vector<std::pair<uint64_t, std::string>> metadata_; // (offset, name) for MetadataIndex
    std::vector<uint64_t> metadata_lengths_;
    std::vector<ChunkInfo> chunks_;
    // The open chunk: its records, and per channel (log time, offset in the chunk).
    std::string chunk_;
    std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_;
    uint64_t chunk_t0_ = 0, chunk_t1_ = 0;
    std::string pending_; // Schema and Channel records not yet written (they precede the first chunk)
    uint64_t message_count_ = 0, t_first_ = 0, t_last_ = 0;
    std::map<uint16_t, uint64_t> per_channel_;
    std::map<uint16_t, uint32_t> sequence_;
};

// ------------------------------------------------------------------ reading

struct Schema {
    uint16_t id = 0;
    std::string name, encoding, data;
};
struct Channel {
    uint16_t id = 0, schema_id = 0;
    std::string topic, message_encoding;
    StringMap metadata;
};
struct Message {
    uint16_t channel = 0;
    uint32_t sequence = 0;
    uint64_t log_time = 0, publish_time = 0;
    // The message's bytes: in the file's bytes (top level, uncompressed
    // chunk) or in File::chunk_data (compressed chunk).
    const uint8_t *data = nullptr;
    size_t length = 0;
    // Where errors about the message point: the byte of its data in the
    // file, or of its Chunk record when that is compressed.
    size_t offset = 0;
};
struct Metadata {
    std::string name;
    StringMap entries;
};

struct File {
    File() = default;
    File(File &&) = default;
    File &operator=(File &&) = default;
    File(const File &) = delete; // messages point into chunk_data
    File &operator=(const File &) = delete;
    std::string profile, library;
    std::map<uint16_t, Schema> schemas;
    std::map<uint16_t, Channel> channels;
    std::vector<Message> messages; // in file order
    // Decompressed chunks the messages point into (not zero-filled first: a
    // chunk announcing more than its data makes costs no memory for the rest).
    struct Buffer {
        std::unique_ptr<uint8_t[]> bytes;
        size_t size = 0;
    };
    std::vector<Buffer> chunk_data;
    std::vector<Metadata> metadata;
    bool complete = false; // DataEnd, footer and closing magic all found
    // Set when the file ends before its footer (a recorder killed, a disk
    // full): every complete record before the cut is kept.
    uint64_t truncated_bytes = 0;
    std::string warning;
};

// Upper bounds on what a hostile file can make the reader allocate beyond
// the file itself: ids and channels are 16-bit in MCAP anyway.
// 16 M messages: 2 GiB of cdm's recording holds about 7 M.
constexpr size_t kMaxMessages = size_t(16) << 20;
// Decompressed bytes of all chunks together: the cap on a recording's file
// size (replay_format.h's kMaxFileBytes), so a small hostile file cannot
// claim more memory than a large honest one.
constexpr uint64_t kMaxUncompressedBytes = uint64_t(2) << 30;

// Reads the data section: Header, Schemas, Channels, Messages (top level or
// in chunks, uncompressed, zstd or lz4, whose uncompressed CRC is checked
// when not 0), Metadata; skips attachments, indexes and unknown opcodes as
// the specification asks. A chunk is decompressed into exactly the size it
// announces (more or less data is refused), and the announced sizes of all
// chunks together may not pass kMaxUncompressedBytes; another compression
// is refused naming it. The summary
// is only framed (the data section holds everything it repeats). A file
// cut short is accepted with `warning` (the records before the cut); a
// file cut inside its Header, or any malformed record, is refused:
// false and err = "NAME: byte OFFSET: what".
bool parse(const uint8_t *data, size_t size, const std::string &name, File &out, std::string &err);

} // namespace cdm::mcap

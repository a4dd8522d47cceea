// See parser.h: a byte source fed to a Parser in blocks of lines.
#include "calib/dataset/parser.h"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <system_error>
#include <thread>

namespace cdm {
namespace dataset_detail {

namespace {

// The reader's two stages. A line's values (Parser::values: the fields
// split and converted, the bulk of the work) need nothing but the header,
// so they are found for a block of lines on whichever thread is free; the
// rest (Parser::row: the position, its statistics, the checks against
// what came before) runs on the calling thread, block after block in file
// order, so every statistic is summed in the order of a reading in turn,
// bit for bit. A line the value stage leaves (anything but a plain data
// row or a blank or comment line: a header, a field count or a value
// line() refuses) and every line after it in its block go to
// Parser::line, which says what is wrong as a reading in turn would.
struct Block {
    struct Row {
        double v[kDatasetValues];
        double t;
        uint32_t rel, b, e; // its line within the block (0-based), its bytes in text
        bool t_ok;
    };
    std::vector<char> text; // whole lines (the file's last may lack its '\n')
    std::vector<Row> rows;  // the data rows before `slow`
    size_t slow = SIZE_MAX; // byte offset of the first line left to Parser::line
    size_t slow_rel = 0;    // its line within the block
    size_t lines = 0;       // the block's lines, when none is left to Parser::line
    enum { Read, Claimed, Done } state = Read;
};

// The value stage of a block (any thread).
void block_values(const Parser &p, Block &bk, std::vector<std::pair<const char *, const char *>> &f) {
    bk.rows.clear();
    bk.slow = SIZE_MAX;
    bk.lines = 0;
    if (bk.text.size() > UINT32_MAX) { // (a text beyond a file's bound, parse_dataset's: offsets of 32 bits)
        bk.slow = 0;
        bk.slow_rel = 0;
        return;
    }
    const char *const base = bk.text.data(), *const end = base + bk.text.size();
    for (const char *b = base; b < end; ++bk.lines) {
        const char *nl = static_cast<const char *>(memchr(b, '\n', size_t(end - b)));
        const char *le = nl ? nl : end;
        Block::Row r;
        const int k = p.values(b, le, r.v, r.t, r.t_ok, f);
        if (k < 0) {
            bk.slow = size_t(b - base);
            bk.slow_rel = bk.lines;
            return;
        }
        if (k > 0) {
            r.rel = uint32_t(bk.lines);
            r.b = uint32_t(b - base);
            r.e = uint32_t(le - base);
            bk.rows.push_back(r);
        }
        b = nl ? nl + 1 : end;
    }
}

// The row stage of a block whose values are found, on the parser's thread.
bool block_rows(Parser &p, const Block &bk, std::string &err) {
    const size_t base = p.lines();
    const char *const text = bk.text.data();
    for (const auto &r : bk.rows)
        if (!p.row(base + r.rel + 1, r.v, r.t, r.t_ok, text + r.b, text + r.e, err)) return false;
    if (bk.slow == SIZE_MAX) {
        p.set_lines(base + bk.lines);
        return true;
    }
    p.set_lines(base + bk.slow_rel);
    const char *const end = text + bk.text.size();
    for (const char *b = text + bk.slow; b < end;) {
        const char *nl = static_cast<const char *>(memchr(b, '\n', size_t(end - b)));
        if (!p.line(b, nl ? nl : end, err)) return false;
        b = nl ? nl + 1 : end;
    }
    return true;
}

constexpr size_t kBlock = size_t(1) << 18, kAhead = 4;

// The input in blocks of whole lines of about kBlock bytes (a line longer
// than that is held whole).
class BlockSource {
public:
    explicit BlockSource(const std::function<long(char *, size_t)> &read) : read_(read) {}
    // The next block: 1, or 0 at the end, or -1 once a read failed (its
    // whole lines before the failure come first, as a block: 1).
    int next(Block &bk) {
        if (failed_) return -1;
        bk.text.swap(carry_);
        carry_.clear();
        for (;;) {
            if (eof_) return bk.text.empty() ? 0 : 1;
            const size_t have = bk.text.size();
            bk.text.resize(have + kBlock);
            const long n = read_(bk.text.data() + have, kBlock);
            if (n < 0) {
                failed_ = true;
                bk.text.resize(have);
                const void *nl = memrchr(bk.text.data(), '\n', have);
                if (!nl) return -1;
                bk.text.resize(size_t(static_cast<const char *>(nl) - bk.text.data()) + 1);
                return 1; // its whole lines; the failure next time
            }
            bk.text.resize(have + size_t(n));
            if (n == 0) {
                eof_ = true;
                continue;
            }
            const void *nl = memrchr(bk.text.data() + have, '\n', size_t(n));
            if (!nl) continue; // no line ends yet: one longer than a block is held whole
            const size_t cut = size_t(static_cast<const char *>(nl) - bk.text.data()) + 1;
            carry_.assign(bk.text.begin() + long(cut), bk.text.end());
            bk.text.resize(cut);
            return 1;
        }
    }

private:
    const std::function<long(char *, size_t)> &read_;
    std::vector<char> carry_; // bytes read after the last block's last '\n'
    bool eof_ = false, failed_ = false;
};

// The blocks read and waiting, in file order (the parser's thread pushes
// and pops), and the helper thread that finds their values ahead. The
// helper ends however the reading does (an error, a tap that throws).
struct ValueStage {
    std::mutex mu;
    std::condition_variable cv;
    std::deque<Block *> queue;
    bool stop = false;
    std::thread helper;

    ~ValueStage() {
        if (!helper.joinable()) return;
        {
            std::lock_guard<std::mutex> lk(mu);
            stop = true;
        }
        cv.notify_all();
        helper.join();
    }
    bool any_read() const {
        return std::any_of(queue.begin(), queue.end(), [](Block *q) { return q->state == Block::Read; });
    }
    Block *claim() { // under mu
        for (Block *b : queue)
            if (b->state == Block::Read) {
                b->state = Block::Claimed;
                return b;
            }
        return nullptr;
    }
    void done(Block *b) {
        {
            std::lock_guard<std::mutex> lk(mu);
            b->state = Block::Done;
        }
        cv.notify_all();
    }
    void push(Block *b) {
        {
            std::lock_guard<std::mutex> lk(mu);
            b->state = Block::Read;
            queue.push_back(b);
        }
        cv.notify_all();
    }
    // The helper: claims the first block waiting, finds its values.
    void start_helper(const Parser &p) {
        try {
            helper = std::thread([this, &p] {
                std::vector<std::pair<const char *, const char *>> fields;
                for (;;) {
                    Block *b;
                    {
                        std::unique_lock<std::mutex> lk(mu);
                        cv.wait(lk, [&] { return stop || any_read(); });
                        if (stop) return;
                        b = claim();
                    }
                    try {
                        block_values(p, *b, fields);
                    } catch (...) { // (out of memory): the block's lines go to Parser::line, on the parser's thread
                        b->rows.clear();
                        b->slow = 0;
                        b->slow_rel = 0;
                    }
                    done(b);
                }
            });
        } catch (const std::system_error &) {
            // in turn, on this thread
        }
    }
    // front's values: found here, or by the helper (this thread meanwhile
    // finds another's).
    void wait_values(const Parser &p, Block *front, std::vector<std::pair<const char *, const char *>> &f) {
        for (;;) {
            Block *mine;
            {
                std::unique_lock<std::mutex> lk(mu);
                cv.wait(lk, [&] { return front->state != Block::Claimed || any_read(); });
                if (front->state == Block::Done) return;
                mine = front->state == Block::Read ? front : claim();
                mine->state = Block::Claimed;
            }
            block_values(p, *mine, f);
            done(mine);
        }
    }
};

} // namespace

// Feeds `read(buf, n)` (bytes read, 0 at the end, < 0 on error) to the
// parser line by line, in blocks of whole lines of about kBlock bytes (a
// line longer than that is held whole), with at most kAhead blocks read
// ahead: memory stays bounded by the file's own bound (io::kDatasetMaxBytes;
// five blocks of very long lines may hold most of it) and otherwise by the
// blocks. Once the header is read and two blocks wait, a second thread
// finds the values of blocks ahead while this one takes the rows of the
// block in turn (Block); in turn on this thread alone when the input is
// shorter, the machine has one processor, or no thread can be started.
// read_error (optional): set when the failure returned is read's (a fault
// in the lines read before it is returned first, as in turn).
bool stream_lines(const std::function<long(char *, size_t)> &read, Parser &p, std::string &err, bool *read_error) {
    BlockSource source(read);
    // A read that failed (err says why) ends the reading; the lines read
    // before it are still taken first, as a reading in turn would have
    // taken them, and a fault among them is the error.
    auto read_failed = [&] {
        if (read_error) *read_error = true;
        return false;
    };
    std::vector<std::pair<const char *, const char *>> f;
    std::vector<std::unique_ptr<Block>> pool;
    for (size_t k = 0; k <= kAhead; ++k) pool.push_back(std::make_unique<Block>());
    // In turn until the header is read (every line to Parser::line).
    Block *first = pool[0].get();
    while (!p.have_header()) {
        const int r = source.next(*first);
        if (r < 0) return read_failed();
        if (r == 0) return p.finish(err);
        first->rows.clear();
        first->slow = 0;
        first->slow_rel = 0;
        if (!block_rows(p, *first, err)) return false;
    }
    ValueStage stage;
    // The helper is started once two blocks wait (a shorter input is read in turn).
    bool helper_tried = std::thread::hardware_concurrency() <= 1;
    std::vector<Block *> spare;
    for (auto &b : pool) spare.push_back(b.get());
    for (;;) {
        while (stage.queue.size() < kAhead && !spare.empty()) {
            Block *b = spare.back();
            const int r = source.next(*b);
            if (r < 0 && stage.queue.empty()) return read_failed();
            if (r <= 0) break;
            spare.pop_back();
            stage.push(b);
        }
        if (stage.queue.empty()) break;
        if (!helper_tried && stage.queue.size() >= 2) {
            helper_tried = true;
            stage.start_helper(p);
        }
        Block *front = stage.queue.front();
        stage.wait_values(p, front, f);
        if (!block_rows(p, *front, err)) return false;
        {
            std::lock_guard<std::mutex> lk(stage.mu);
            stage.queue.pop_front();
        }
        spare.push_back(front);
    }
    return p.finish(err);
}

} // namespace dataset_detail
} // namespace cdm

#include "calib/dataset/dataset.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>

#include "calib/dataset/glitches.h"
#include "calib/dataset/parser.h"

namespace cdm {

const char *const kDatasetColumns[kDatasetValues] = {"point", "x_ref", "y_ref", "z_ref", "l1", "l2", "l3", "l4"};

DatasetFault dataset_value_fault(int column, double v) {
    if (!std::isfinite(v)) return DatasetFault::NotFinite;
    if (column == 0) return v != std::floor(v) || std::fabs(v) > 9e15 ? DatasetFault::NotInteger : DatasetFault::None;
    if (column < 4) return std::fabs(v) > kDatasetMaxRefMm ? DatasetFault::OutOfRange : DatasetFault::None;
    return !(v > 0) || v > kDatasetMaxLengthMm ? DatasetFault::OutOfRange : DatasetFault::None;
}

std::string dataset_fault_text(DatasetFault f, int column, const std::string &name, const std::string &shown) {
    switch (f) {
    case DatasetFault::None: break;
    case DatasetFault::NotFinite: return name + " is not a finite number: '" + shown + "'";
    case DatasetFault::NotInteger: return name + " must be an integer id, got " + shown;
    case DatasetFault::OutOfRange:
        return column < 4 ? name + " = " + shown + " mm is beyond the sane range of +-5000 mm (wrong unit?)"
                          : name + " must be a positive length in mm, at most 10000 (got " + shown + ")";
    }
    return name + " is accepted";
}

struct DatasetSource {
    bool is_file = false;
    io::FileReader file; // the descriptor load_dataset() opened
    std::string text;    // what parse_dataset() was given
};

namespace {

using dataset_detail::Parser;
using dataset_detail::Tap;
using dataset_detail::stream_lines;
using Visit = std::function<void(size_t, const double *)>;

// Reads the source's bytes in order.
struct SourceReader {
    const DatasetSource &s;
    std::string &err;
    size_t off = 0;
    long operator()(char *buf, size_t n) {
        long r;
        if (s.is_file) {
            r = s.file.pread(buf, n, off, err);
        } else {
            r = long(std::min(n, s.text.size() - off));
            std::memcpy(buf, s.text.data() + off, size_t(r));
        }
        if (r > 0) off += size_t(r);
        return r;
    }
};

// The glitch screen (glitches.h), on a dataset just parsed by `p`:
// the suspect positions' samples are read again, and when some are set
// aside the dataset is parsed once more without them.
bool screen_glitches(Dataset &d, Parser &p, std::string &err) {
    const GlitchScreen s = glitch_suspects(d, p.range());
    d.glitch_z = s.z;
    std::copy(std::begin(s.scale), std::end(s.scale), d.glitch_scale);
    if (!s.any()) return true;
    GlitchJudge judge(d, s);
    const Tap collect = [&](size_t g, size_t row, size_t line, const double *l) {
        if (!s.suspect[g]) return;
        ScreenSample x;
        x.g = g, x.row = row, x.line = line;
        std::copy(l, l + 4, x.l);
        judge.add(x);
    };
    {
        Dataset again;
        Parser p2(d.path, again, &d, &collect);
        if (!stream_lines(SourceReader{*d.source, err}, p2, err)) return false;
    }
    std::vector<DatasetGlitch> glitches;
    std::vector<size_t> rows;
    judge.finish(glitches, rows);
    d.glitch_held = judge.peak_samples();
    if (judge.abandoned()) d.glitch_z = 0; // gave up (kGlitchMaxHeld): not screened
    if (rows.empty()) return true;
    Dataset clean;
    Parser p3(d.path, clean, nullptr, nullptr, &rows);
    if (!stream_lines(SourceReader{*d.source, err}, p3, err)) return false;
    clean.source = d.source;
    clean.glitches = std::move(glitches);
    clean.excluded_rows = std::move(rows);
    clean.glitch_z = d.glitch_z;
    clean.glitch_held = d.glitch_held;
    std::copy(std::begin(d.glitch_scale), std::end(d.glitch_scale), clean.glitch_scale);
    d = std::move(clean);
    return true;
}

bool parse_source(const std::shared_ptr<const DatasetSource> &s, const std::string &src, Dataset &out,
                  std::string &err) {
    Dataset d;
    Parser p(src, d, nullptr, nullptr);
    if (!stream_lines(SourceReader{*s, err}, p, err)) return false;
    d.source = s;
    if (!screen_glitches(d, p, err)) return false;
    out = std::move(d);
    return true;
}
} // namespace

bool parse_dataset(const std::string &text, const std::string &src, Dataset &out, std::string &err) {
    auto s = std::make_shared<DatasetSource>();
    s->text = text;
    return parse_source(s, src, out, err);
}

bool load_dataset(const std::string &path, Dataset &out, std::string &err, bool *io_failure) {
    if (io_failure) *io_failure = false;
    auto s = std::make_shared<DatasetSource>();
    s->is_file = true;
    if (!s->file.open(path, io::kDatasetMaxBytes, err, "dataset")) {
        if (io_failure) *io_failure = true;
        return false;
    }
    // A read error part-way is an I/O failure too, not a malformed file.
    bool read_failed = false;
    Dataset d;
    Parser p(path, d, nullptr, nullptr);
    if (!stream_lines(SourceReader{*s, err}, p, err, &read_failed)) {
        if (io_failure) *io_failure = read_failed;
        return false;
    }
    d.source = std::move(s);
    if (!screen_glitches(d, p, err)) {
        if (io_failure) *io_failure = true; // the file could not be read again, or changed meanwhile
        return false;
    }
    out = std::move(d);
    return true;
}

bool for_each_sample(const Dataset &d, const Visit &visit, std::string &err) {
    if (!d.source) {
        err = d.path + ": the dataset's rows cannot be read again (it was not read by load_dataset or parse_dataset)";
        return false;
    }
    Dataset again;
    const Tap tap = [&](size_t g, size_t, size_t, const double *l) { visit(g, l); };
    Parser p(d.path, again, &d, &tap, &d.excluded_rows, &d.excluded_points);
    return stream_lines(SourceReader{*d.source, err}, p, err);
}

bool without_points(const Dataset &d, const std::vector<long> &points, Dataset &out, std::string &err) {
    if (!d.source) {
        err = d.path + ": the dataset's rows cannot be read again (it was not read by load_dataset or parse_dataset)";
        return false;
    }
    std::vector<long> skip = d.excluded_points;
    skip.insert(skip.end(), points.begin(), points.end());
    std::sort(skip.begin(), skip.end());
    skip.erase(std::unique(skip.begin(), skip.end()), skip.end());
    Dataset again;
    Parser p(d.path, again, nullptr, nullptr, &d.excluded_rows, &skip);
    if (!stream_lines(SourceReader{*d.source, err}, p, err)) return false;
    if (again.pos.empty()) {
        err = d.path + ": no position would be left without points " + std::to_string(skip.size()) + " listed";
        return false;
    }
    // The heights stay the first read's (find_heights decided them on every
    // position): setting positions aside must not turn an off-height
    // reference into a height of its own (the tenth it may be of the jig
    // grows as the jig shrinks), nor a thinned height into an off-height
    // value. Only a height none of whose positions is left goes.
    {
        // (sorted x values and a search per height: a scattered jig has as
        // many heights as positions)
        std::vector<double> xs;
        for (const JigHole &jp : again.pos) xs.push_back(jp.ref[0]);
        std::sort(xs.begin(), xs.end());
        std::vector<double> kept;
        for (double h : d.heights) {
            const auto it = std::lower_bound(xs.begin(), xs.end(), h - 1e-6);
            if (it != xs.end() && std::fabs(*it - h) < 1e-6) kept.push_back(h);
        }
        std::vector<long> off;
        for (long p : d.off_height_points)
            if (!std::binary_search(skip.begin(), skip.end(), p)) off.push_back(p);
        if (!kept.empty()) {
            again.heights = std::move(kept);
            again.off_height_points = std::move(off);
        }
    }
    again.source = d.source;
    again.glitches = d.glitches;
    again.excluded_rows = d.excluded_rows;
    again.glitch_z = d.glitch_z;
    again.glitch_held = d.glitch_held;
    std::copy(std::begin(d.glitch_scale), std::end(d.glitch_scale), again.glitch_scale);
    again.excluded_points = std::move(skip);
    out = std::move(again);
    return true;
}

} // namespace cdm

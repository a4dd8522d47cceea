// Jig datasets: CSV `point,x_ref,y_ref,z_ref,l1,l2,l3,l4` (extra columns
// ignored and reported), grouped into per-position statistics as the rows
// stream in: memory grows with the positions, not with the samples at each.
// The samples themselves are not kept; the few statistics that need every
// sample (the per-sample maxima, the seed's per-sample triangulation) read
// them again with for_each_sample() (docs/calibration.md, "Per-position
// statistics").
#pragma once

#include <array>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "io/file.h"

namespace cdm {

struct JigHole {
    long point = 0;
    double ref[3] = {0, 0, 0};
    int n = 0;               // samples
    double mean[4] = {0, 0, 0, 0};
    double cov[4][4] = {};   // sample covariance of the readings (n-1; 0 when n = 1)
    // Acquisition order, for drift over the session. Rows
    // of a jig CSV are in acquisition order; without a time column the time
    // is the mean row index times kDatasetNominalRowPeriodS (a nominal
    // figure, so a drift rate from it is per nominal second).
    double mean_row = 0;     // mean 0-based data-row index of its samples
    double t_s = 0;          // mean acquisition time (s)
};

// Nominal time between two jig CSV rows when the file has no time column.
constexpr double kDatasetNominalRowPeriodS = 0.01;

// Distinct readings kept per cable to find the readings' resolution; beyond
// it the resolution is an upper bound (see Dataset::resolution).
constexpr size_t kDatasetResolutionValues = size_t(1) << 16;

struct DatasetSource; // where the rows can be read again (read.cpp)

// A sample set aside as a glitch: one reading far from the rest of its
// position's samples (a spike of the pot's wiper, a dropped ADC bit, a bumped
// cable). See screen_glitches in glitches.h for the test.
struct DatasetGlitch {
    size_t line = 0;       // 1-based line of the file
    long point = 0;
    int cable = 0;         // 1-4: the reading that departs most (in units of its scale)
    double reading = 0;    // mm
    double median = 0;     // the position's median reading of that cable (mm)
    double z = 0;          // |reading - median| / the cable's noise scale at that position
};

struct Dataset {
    std::string path;
    size_t rows = 0;
    std::vector<std::string> ignored_columns;
    std::vector<JigHole> pos;                 // in order of first appearance
    // The fixture heights, sorted: the x_ref values positions share, each by
    // at least two positions and either by a quarter as many as the fullest
    // height or on holes the nearest such height also has (a height with
    // fewer holes, or recorded part-way). A position whose x_ref no other
    // position has, or a few share on holes missing from the nearest height
    // (a reference typed or measured off its height, a probe seated 1 mm
    // high), is not a height of its own when such positions are a tenth of
    // the jig or fewer: it is listed in off_height_points, grouped with the
    // nearest height for the fixture and the neighbours (diag::make_grid),
    // and judged by the model on the reference as written. Otherwise (references scattered in x)
    // every distinct x_ref.
    std::vector<double> heights;
    std::vector<long> off_height_points;
    // Per cable, the smallest step between distinct readings (> 1e-9 mm;
    // 0 when there is none): the ADC count through the nominal scale, or the
    // CSV's last digit for unquantised data. Exact while a cable shows at
    // most kDatasetResolutionValues distinct readings; beyond that, the
    // smallest step among the first that many (an upper bound on it).
    double resolution[4] = {0, 0, 0, 0};
    std::shared_ptr<const DatasetSource> source;
    // Samples set aside as glitches (the screen in glitches.h):
    // left out of every position's statistics and of for_each_sample; `rows`
    // still counts them. excluded_rows: their 0-based data-row indices, sorted.
    std::vector<DatasetGlitch> glitches;
    std::vector<size_t> excluded_rows;
    double glitch_z = 0;         // the screen's threshold (robust sd), 0 when it did not run
    double glitch_scale[4] = {}; // the cables' pooled noise scale it used (mm)
    size_t glitch_held = 0;      // most samples the screen held at once (one position's in a jig file)
    // Points left out whole (without_points: the diagnosis' outliers),
    // sorted; their rows are still counted in `rows`.
    std::vector<long> excluded_points;
};

// Reads the rows of `d` again, in file order, and calls visit(position
// index into d.pos, the four readings) for each row not set aside as a
// glitch; the same parser and checks
// as the first read. A file is read through the descriptor load_dataset()
// opened (a file replaced by rename since is still the one loaded); if its
// content changed in place the pass stops with an error naming the line.
// False + err also when `d` has no source (not made by the functions below).
bool for_each_sample(const Dataset &d, const std::function<void(size_t, const double *)> &visit, std::string &err);

// Sane magnitudes (mm). A jig reference beyond 5 m from the origin, or a
// cable length outside (0, 10 m], is a unit error or corrupt data, not a
// master of this kind (frames of 10 mm..5 m, see io/device_json.h).
constexpr double kDatasetMaxRefMm = 5000.0;
constexpr double kDatasetMaxLengthMm = 10000.0;

// The columns every row has, in the writer's order.
constexpr int kDatasetValues = 8;
extern const char *const kDatasetColumns[kDatasetValues]; // point, x_ref, y_ref, z_ref, l1..l4

// Why the reader refuses one value of a row: the one rule, which
// load_dataset applies to what it reads and DatasetWriter to what it is
// about to write, so the writer never writes a row the reader refuses.
enum class DatasetFault {
    None,
    NotFinite,  // NaN or infinite (the reader also says so of a field that is no number)
    NotInteger, // point: not an integer id within +-9e15
    OutOfRange, // a reference beyond kDatasetMaxRefMm, a length outside (0, kDatasetMaxLengthMm]
};
// `column` indexes kDatasetColumns.
DatasetFault dataset_value_fault(int column, double v);
// The reader's words for a fault of value `shown` (as the file or the
// caller has it) of the value called `name`, e.g. "l2 must be a positive
// length in mm, at most 10000 (got -1)".
std::string dataset_fault_text(DatasetFault f, int column, const std::string &name, const std::string &shown);

// Parses and groups, streaming (load_dataset reads the file in blocks of
// whole lines of 256 KiB, at most four ahead, a line longer than that held
// whole; on a longer input a second thread converts the fields of blocks
// ahead while the rows are grouped in file order, so every statistic is
// the same, bit for bit, as when read in turn). On error returns false with `err` naming the file,
// line and column (1-based), e.g. "jig.csv:17:6: l2 is not a number: 'abc'".
// Refuses duplicate columns, non-finite values and magnitudes outside the
// ranges above; a field echoed in a message is cut to ~40 characters.
// `io_failure` (optional) tells a file that could not be read (missing,
// special, too large: CDM_ERR_IO) from one that does not parse.
// Glitches are screened as the file is loaded (glitches.h): when
// some position's readings spread wider than the noise allows, the file is
// read again for those positions' samples, and once more without the
// samples set aside (Dataset::glitches says which, and why).
bool load_dataset(const std::string &path, Dataset &out, std::string &err, bool *io_failure = nullptr);
bool parse_dataset(const std::string &text, const std::string &source, Dataset &out, std::string &err);

// `d` read again without the rows of `points` (any order; added to those
// already left out), glitches still set aside: the diagnosis' second round
// without the positions it set aside as outliers. False + err when the rows
// cannot be read again, or no position would be left.
bool without_points(const Dataset &d, const std::vector<long> &points, Dataset &out, std::string &err);

// The samples the glitch screen set aside, as JSON (the diagnosis's and
// cdm_fit's "glitches"): whether it ran, the count, the test, the first
// kGlitchesListed by line.
constexpr size_t kGlitchesListed = 100;
nlohmann::json glitches_json(const Dataset &d);

// The one dataset writer: the header, then add_row() per sample, then
// commit() (atomic: io::AtomicFile). Rows are written as they come, so a
// recording need not be held in memory. Destroyed without commit(): no file.
// Numbers are written with '.' as the decimal point whatever the process's
// locale (std::to_chars), four decimals (six for t_s).
//
// Refusals come in two kinds. The caller's mistake (*usage set): the row is
// refused before anything is written and the writer goes on as if it had
// not been given. A failed write or commit (I/O): the file is abandoned, and
// every later add_row() and commit() fails with that first failure's text.
class DatasetWriter {
public:
    bool open(const std::string &path, const std::vector<std::string> &protect_paths, std::string &err);
    // t_s finite: the row's acquisition time, written in a t_s column. The
    // first row decides whether the file has the column; a later row of the
    // other kind is refused (*usage set: the caller's mistake, not I/O).
    // Refused too (*usage): a row load_dataset would refuse, judged on the
    // values as the file would hold them (dataset_value_fault; a length of
    // 1e-5 mm is written 0.0000, not positive), a point whose reference
    // differs from its first row's (as written), and any row after commit().
    // The text names the point, the argument (ref_mm[k] / lengths_mm[k], the
    // C API's names) and its value.
    bool add_row(long point, const double ref[3], const double lengths[4], std::string &err, double t_s = NAN,
                 bool *usage = nullptr);
    // A second commit() is refused (*usage), and so is a commit with no row
    // (the file would be one the reader refuses, in place of what `path`
    // held): nothing is written, and rows can still be added. After a
    // failure, see above.
    bool commit(std::string &err, bool *usage = nullptr);

private:
    io::AtomicFile f_;
    std::string path_, buf_;
    int timed_ = -1; // -1: no row yet; 0: no t_s column; 1: t_s column
    bool committed_ = false;
    std::string failed_; // the write or commit failure that ended the file (sticky)
    // Each point's reference as written: the reader holds a point to it.
    std::unordered_map<long, std::array<double, 3>> refs_;
};



} // namespace cdm

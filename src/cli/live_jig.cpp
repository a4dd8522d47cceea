// See live_jig.h.
#include "live_jig.h"

#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

#include <Eigen/Dense>

#include <cdm/cdm.h>
#include "commands.h"

namespace cdm::cli {

namespace {

using nlohmann::json;

// The 95 % quantile of chi-square with 3 degrees of freedom: the ellipsoid
// {e : e' C^-1 e <= q} holds a Gaussian error with probability 0.95.
constexpr double kChi2Of3At95 = 7.814727903251178;

std::string joined(const std::vector<std::string> &v, const char *sep) {
    std::string s;
    for (size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
    return s;
}

// A libcdm call's JSON result (rc and text from a call made before this
// one: never in the same expression, whose order C++ leaves open); null +
// err (the library's message) when the call failed.
json result_json(int rc, char *text, std::string &err) {
    if (rc != CDM_OK) {
        err = cdm_thread_error();
        cdm_free_string(text);
        return nullptr;
    }
    json j = json::parse(text ? text : "", nullptr, false);
    cdm_free_string(text);
    if (j.is_discarded()) err = "libcdm returned unreadable JSON";
    return j.is_discarded() ? json(nullptr) : j;
}

// The calibration's predicted error at each of `where` (jig frame, taken
// as the device frame: the jig's placement moves a position by well under
// a millimetre, over which the covariance does not change): the 95 %
// ellipsoid's longest semi-axis. Positions the model cannot place are
// counted apart.
json predicted_error(const std::string &cal_path, const std::vector<std::array<double, 3>> &where, std::string &err) {
    cdm_calibration *cal = nullptr;
    if (cdm_calibration_load(cal_path.c_str(), &cal) != CDM_OK) {
        err = cdm_thread_error();
        return nullptr;
    }
    double sum = 0, worst = 0;
    size_t placed = 0, unplaced = 0;
    for (const auto &p : where) {
        double c[9];
        const int rc = cdm_calibration_position_covariance(cal, p.data(), c);
        if (rc == CDM_ERR_UNSUPPORTED) {
            err = cdm_thread_error();
            cdm_calibration_free(cal);
            return nullptr;
        }
        if (rc != CDM_OK) {
            ++unplaced;
            continue;
        }
        const Eigen::Matrix3d C = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(c);
        const double r = std::sqrt(kChi2Of3At95 * std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(
                                                                     C, Eigen::EigenvaluesOnly)
                                                                     .eigenvalues()
                                                                     .maxCoeff()));
        sum += r, worst = std::max(worst, r), ++placed;
    }
    cdm_calibration_free(cal);
    if (placed == 0) {
        err = "the fitted model places none of the session's positions";
        return nullptr;
    }
    return {{"mean", sum / double(placed)}, {"worst", worst}, {"positions", placed}, {"unplaced", unplaced}};
}

// The session's positions outside the measured volume (where a prediction
// extrapolates): a height outside the measured heights' span, or a hole
// outside the span of the holes measured (at any height: the plate is the
// same at every height).
template <class Data>
size_t outside(const Data &data, const std::vector<std::array<double, 3>> &session) {
    std::array<double, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (const auto &p : data)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p->ref[a]), hi[a] = std::max(hi[a], p->ref[a]);
    size_t n = 0;
    for (const auto &q : session) {
        bool in = true;
        for (int a = 0; a < 3; ++a) in = in && q[a] >= lo[a] - 1e-6 && q[a] <= hi[a] + 1e-6;
        n += in ? 0 : 1;
    }
    return n;
}

} // namespace

LiveJig::LiveJig(const LiveOptions &o, LiveSession s, bool wait) : o_(o), s_(std::move(s)), wait_(wait) {
    if (o_.every <= 0) o_.every = std::max<int>(10, int(s_.positions.size() / 25));
    thread_ = std::thread(&LiveJig::run, this);
}

LiveJig::~LiveJig() {
    finish();
    if (!dir_.empty()) {
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }
}

std::array<double, 3> live_device_frame(const std::string &path) {
    char *text = nullptr;
    if (cdm_device_file_read(path.c_str(), &text) != CDM_OK) throw UsageError("--device: " + std::string(cdm_thread_error()));
    const json j = json::parse(text);
    cdm_free_string(text);
    return {j.at("a_mm").get<double>(), j.at("b_mm").get<double>(), j.at("m_mm").get<double>()};
}

std::string live_frame_mismatch(const std::string &path, const std::array<double, 3> &file,
                                const std::array<double, 3> &device) {
    constexpr double kToleranceMm = 1.0; // the device's check of a calibration's frame
    static const char *const kNames[3] = {"a_mm", "b_mm", "m_mm"};
    std::string out;
    for (int k = 0; k < 3; ++k)
        if (!(std::fabs(file[k] - device[k]) <= kToleranceMm))
            out += std::string(out.empty() ? "" : ", ") + kNames[k] + " " + num(file[k]) + " (" + path + ") vs " +
                   num(device[k]) + " (the device)";
    if (out.empty()) return out;
    return "--device " + path + " is another frame: " + out +
           "; the analysis would diagnose another device (leave --device out to use the device's own)";
}

bool LiveJig::start(double a_mm, double b_mm, double m_mm, std::string &err) {
    const char *tmp = std::getenv("TMPDIR");
    std::string templ = std::string(tmp && *tmp ? tmp : "/tmp") + "/cdm-live-XXXXXX";
    if (!mkdtemp(templ.data())) {
        err = "cannot make a working directory in " + std::string(tmp && *tmp ? tmp : "/tmp") + ": " +
              std::strerror(errno);
        return false;
    }
    std::lock_guard<std::mutex> lock(mu_);
    dir_ = templ;
    device_json_ = o_.device;
    if (device_json_.empty()) {
        device_json_ = dir_ + "/device.json";
        std::ofstream f(device_json_);
        f << json{{"a_mm", a_mm}, {"b_mm", b_mm}, {"m_mm", m_mm}}.dump() << "\n";
        if (!f.flush()) {
            err = "cannot write " + device_json_ + ": " + std::strerror(errno);
            return false;
        }
    }
    try { // the analysis hands these paths to libcdm inside JSON options
        (void)json{dir_, device_json_}.dump();
    } catch (const json::exception &) {
        err = "the working directory " + dir_ + " or the device file " + device_json_ +
              " is not a UTF-8 path (set TMPDIR, or --device, to one)";
        return false;
    }
    started_ = true;
    cv_.notify_all();
    return true;
}

bool LiveJig::add(size_t index, int point, const double ref[3], const std::vector<std::array<double, 4>> &rows,
                  const std::vector<double> &t_s) {
    std::unique_lock<std::mutex> lock(mu_);
    data_.push_back(std::make_shared<const Position>(Position{index, point, {ref[0], ref[1], ref[2]}, rows, t_s}));
    const size_t n = data_.size();
    if (n % size_t(o_.every) == 0 || index + 1 >= s_.positions.size()) {
        requested_ = n;
        cv_.notify_all();
        if (wait_) cv_.wait(lock, [&] { return done_ >= n || quit_; });
    }
    return stop_;
}

bool LiveJig::stop_requested() const {
    std::lock_guard<std::mutex> lock(mu_);
    return stop_;
}

std::vector<std::string> LiveJig::take_messages() {
    std::lock_guard<std::mutex> lock(mu_);
    std::vector<std::string> v;
    v.swap(messages_);
    return v;
}

json LiveJig::finish() {
    {
        std::lock_guard<std::mutex> lock(mu_);
        quit_ = true;
        // The positions kept since the last update asked for: one more, on
        // every position (a session cut short, or ending on a position
        // whose samples were all refused, still gets its last word).
        if (started_ && data_.size() > requested_) requested_ = data_.size();
        cv_.notify_all();
    }
    if (thread_.joinable()) thread_.join();
    std::lock_guard<std::mutex> lock(mu_);
    json last = updates_.empty() ? json(nullptr) : updates_.back();
    return {{"updates", updates_},
            {"every", o_.every},
            {"target_mm", o_.target_mm},
            {"stable", o_.stable},
            {"stopped", stop_},
            {"model", last.is_null() ? json(nullptr) : last["model"]},
            {"predicted_radius95_mm", last.is_null() ? json(nullptr) : last["predicted_radius95_mm"]}};
}

void LiveJig::run() {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
        cv_.wait(lock, [&] { return quit_ || (started_ && requested_ > done_); });
        // After finish(), an update asked for and not begun is still made
        // (the session's last positions), then the thread ends.
        if (!(started_ && requested_ > done_)) return;
        const size_t n = requested_;
        std::vector<std::shared_ptr<const Position>> data(data_.begin(), data_.begin() + long(n));
        lock.unlock();
        json u;
        try {
            u = update(data);
        } catch (const std::exception &e) { // the analysis fails, never the recording
            u = {{"positions", n}, {"of", s_.positions.size()}, {"error", std::string("live analysis: ") + e.what()}};
        }
        lock.lock();
        try {
            judge(u);
        } catch (const std::exception &e) {
            u["decision"] = "error";
            u["text"] = std::string("live: no update (live analysis: ") + e.what() + ")";
        }
        if (u["decision"] == "next" && !quit_) {
            lock.unlock();
            try {
                advise(data, u);
            } catch (const std::exception &e) {
                u["next_error"] = e.what();
            }
            lock.lock();
        }
        updates_.push_back(u);
        messages_.push_back(u["text"].get<std::string>());
        done_ = n;
        cv_.notify_all();
    }
}

bool LiveJig::write_snapshot(const std::vector<std::shared_ptr<const Position>> &data, std::string &err) const {
    cdm_dataset_writer *w = nullptr;
    if (cdm_dataset_writer_open((dir_ + "/data.csv").c_str(), nullptr, 0, &w) != CDM_OK) {
        err = cdm_thread_error();
        return false;
    }
    bool ok = true;
    for (const auto &p : data)
        for (size_t k = 0; ok && k < p->rows.size(); ++k)
            ok = cdm_dataset_writer_add_at(w, p->point, p->ref.data(), p->rows[k].data(), p->t_s[k]) == CDM_OK;
    ok = ok && cdm_dataset_writer_commit(w) == CDM_OK;
    if (!ok) err = cdm_thread_error();
    cdm_dataset_writer_free(w);
    return ok;
}

// The data so far diagnosed, then fitted with the recommended model, whose
// covariance gives the predicted error at every position of the session.
json LiveJig::update(const std::vector<std::shared_ptr<const Position>> &data) {
    const double t0 = now_s();
    json u = {{"positions", data.size()}, {"of", s_.positions.size()}, {"model", nullptr}, {"explained", false},
              {"predicted_radius95_mm", nullptr}};
    std::string err;
    const std::string csv = dir_ + "/data.csv", cal = dir_ + "/calibration.json";
    char *text = nullptr;
    json d;
    if (write_snapshot(data, err)) {
        const int rc = cdm_diagnose(csv.c_str(), device_json_.c_str(), nullptr, nullptr, nullptr, &text);
        d = result_json(rc, text, err);
    }
    const json rec = d.is_object() ? d.value("recommended", json::object()) : json::object();
    if (!d.is_null() && !(rec.contains("effects") && rec["effects"].is_array()))
        err = "the diagnosis recommends no model";
    if (err.empty()) {
        u["model"] = rec["effects"];
        u["explained"] = rec.value("explained", false);
        u["negligible_only"] = rec.value("negligible_only", false);
        if (rec["effects"].empty()) {
            u["predicted_radius95_mm"] = {{"mean", 0.0}, {"worst", 0.0}, {"positions", s_.positions.size()},
                                          {"unplaced", 0}, {"about", "the nominal model: nothing fitted"}};
        } else {
            const json fo = {{"effects", rec["effects"]}, {"calibration_out", cal}};
            text = nullptr;
            const int rc = cdm_fit(csv.c_str(), device_json_.c_str(), fo.dump().c_str(), nullptr, nullptr, &text);
            const json f = result_json(rc, text, err);
            if (!f.is_null()) u["predicted_radius95_mm"] = predicted_error(cal, s_.positions, err);
        }
    }
    if (!err.empty()) u["error"] = err;
    u["outside_measured_volume"] = outside(data, s_.positions);
    u["visited"] = data.empty() ? 0 : data.back()->index + 1; // the session's positions walked past
    u["seconds"] = now_s() - t0;
    return u;
}

// The stop rule, and the update's line for the person at the bench.
void LiveJig::judge(json &u) {
    const bool failed = u.contains("error");
    const json none = nullptr;
    const json &m = u.contains("model") ? u["model"] : none;
    const std::vector<std::string> model = m.is_array() ? m.get<std::vector<std::string>>() : std::vector<std::string>{"?"};
    same_ = !failed && m.is_array() && model == last_model_ ? same_ + 1 : 1;
    last_model_ = model;
    u["same_for"] = same_;
    const json &p = u.contains("predicted_radius95_mm") ? u["predicted_radius95_mm"] : none;
    const bool under = p.is_object() && p.value("unplaced", size_t(1)) == 0 && p.value("worst", INFINITY) <= o_.target_mm;
    const size_t out = u.value("outside_measured_volume", size_t(1));
    // The nominal model never stops a session: nothing fitted means nothing
    // predicted, not that the catalogue's effects could have been seen.
    // Explained as the diagnosis's verdict says it: every test passes, or
    // only effects under a tenth of the noise floor are left significant.
    const bool explained = u.value("explained", false), negligible_only = u.value("negligible_only", false);
    const bool determined =
        !failed && (explained || negligible_only) && same_ >= o_.stable && under && out == 0 && !model.empty();
    u["decision"] = determined ? "stop" : failed ? "error" : "next";
    std::string t = "live: " + std::to_string(u.value("positions", size_t(0))) + "/" +
                    std::to_string(u.value("of", size_t(0))) + " positions: ";
    if (failed) {
        t += "no update (" + u["error"].get<std::string>() + ")";
    } else {
        t += "model " + (model.empty() ? std::string("nominal") : joined(model, " + ")) +
             (explained         ? " (explains the data"
              : negligible_only ? " (explains the data to within what matters"
                                : " (does not explain the data yet") +
             ", the same for " + std::to_string(same_) + " update" + (same_ > 1 ? "s" : "") + ")";
        if (p.is_object())
            t += "; predicted error (95 % radius) at the session's positions: mean " +
                 num(std::round(p.value("mean", 0.0) * 1e4) / 1e4) + ", worst " +
                 num(std::round(p.value("worst", 0.0) * 1e4) / 1e4) + " mm (target " + num(o_.target_mm) + ")";
        if (p.is_object() && p.value("unplaced", size_t(0)) > 0)
            t += "; " + std::to_string(p["unplaced"].get<size_t>()) + " positions the model cannot place";
        if (out) t += "; " + std::to_string(out) + " of them outside the measured volume (extrapolated)";
    }
    // The session is ended only while it runs and has positions left.
    if (determined && !quit_ && u.value("visited", s_.positions.size()) < s_.positions.size()) {
        stop_ = true;
        t += "\n  stop: the model is determined";
    } else if (determined) {
        t += "\n  the model is determined";
    }
    u["text"] = t;
}

// "next: measure these holes": the planner's picks for the recommended
// model among the session's positions not yet measured.
void LiveJig::advise(const std::vector<std::shared_ptr<const Position>> &data, json &u) const {
    // The session's positions not measured yet, each once (a plan may
    // visit a hole twice).
    std::set<std::array<double, 3>> seen;
    json measured = json::array(), allowed = json::array();
    for (const auto &p : data) measured.push_back(p->ref), seen.insert(p->ref);
    for (size_t i = data.empty() ? 0 : data.back()->index + 1; i < s_.positions.size(); ++i)
        if (seen.insert(s_.positions[i]).second) allowed.push_back(s_.positions[i]);
    if (allowed.empty()) return;
    json o = {{"positions", std::min<size_t>(size_t(o_.next), allowed.size())},
              {"samples", s_.samples},
              {"holes", s_.holes},
              {"pitch_mm", s_.pitch_mm},
              {"heights_mm", s_.heights_mm},
              {"measured", measured},
              {"allowed", allowed},
              {"device", device_json_}};
    if (u["model"].is_array() && !u["model"].empty()) o["effects"] = u["model"];
    std::string err;
    char *text = nullptr;
    const int rc = cdm_plan(o.dump().c_str(), nullptr, nullptr, &text);
    const json r = result_json(rc, text, err);
    std::string t = u["text"].get<std::string>() + "\n  next: measure these holes: ";
    if (r.is_null()) {
        u["next_error"] = err;
        u["text"] = t + "(the planner: " + err + ")";
        return;
    }
    const json holes = r.value("positions", json::array());
    u["next"] = holes;
    for (size_t i = 0; i < holes.size(); ++i) {
        const json &q = holes[i];
        t += std::string(i ? "; " : "") + "height " + num(q[0].get<double>()) + " mm, y " + num(q[1].get<double>()) +
             " z " + num(q[2].get<double>());
    }
    u["text"] = t;
}

void add_live_options(CLI::App *record, LiveOptions &o) {
    auto *live = record->add_flag(
        "--live", o.on,
        "with --jig: diagnose the session as it is recorded: every few positions the recommended model, the "
        "predicted error at the session's positions, and either the holes to measure next or \"stop: the model is "
        "determined\", which ends the session (every sample is in FILE whatever the analysis does)");
    record->add_option("--live-every", o.every,
                       "positions per live update (0: a 25th of the session's positions, at least 10)")
        ->check(range(0, 1000000))
        ->needs(live);
    record->add_option("--target-mm", o.target_mm,
                       "the live session stops once the predicted error (the 95 % ellipsoid's longest semi-axis) is "
                       "under this at every position of the session")
        ->check(range(1e-6, 1000))
        ->needs(live);
    record->add_option("--stable", o.stable,
                       "updates in a row the recommended model must stay the same before the live session stops")
        ->check(range(1, 1000))
        ->needs(live);
    record->add_option("--next", o.next, "holes the live session advises measuring next")
        ->check(range(1, 1000))
        ->needs(live);
    record->add_option("--device", o.device,
                       "device description JSON for the live analysis (default: the device's nominal geometry)")
        ->needs(live);
}

} // namespace cdm::cli

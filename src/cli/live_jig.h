// A jig session diagnosed as it is recorded (`cdm record --jig --live`).
// Every few positions the data so far is diagnosed (the recommended model),
// fitted with that model, and the fit's covariance propagated to every
// position of the session, measured or not (the 95 % ellipsoid's longest
// semi-axis: cdm_calibration_position_covariance). The session stops by
// itself once the model is determined: the diagnosis explains the data, its
// recommended model (not the nominal one, which has nothing fitted to be
// uncertain about) has not changed for `stable` updates, the predicted
// error is under the target at every position of the session (each placed
// by the model), and none of
// them is an extrapolation (outside the span of the heights, and of the
// holes, measured so far: an effect that only shows there could not have
// been seen). Until then
// the planner (cdm_plan with the data so far as "measured", the session's
// positions left as "allowed") says which holes would help most.
//
// The analysis runs on its own thread and never touches the dataset being
// recorded: the reader hands it each kept position and goes on, so a slow
// update costs no sample. On a source that is not paced by a clock (a
// replay at speed=0, a sim: at realtime=0) the reader waits for each
// update instead, so the same recording gives the same updates and stops
// at the same position at any speed.
#pragma once

#include <array>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

namespace cdm::cli {

struct LiveOptions {
    bool on = false;
    int every = 0;           // positions per update; 0: a 25th of the session's, at least 10
    double target_mm = 0.1;  // the predicted 95 % radius every position of the session must be under
    int stable = 3;          // updates in a row with the same recommended model
    int next = 5;            // holes advised while the session goes on
    std::string device;      // device JSON for the analysis; empty: the device's own nominal geometry
};

// The --device file read and checked before anything opens (an input of
// the session: never written over): its frame {a, b, m} in mm. Throws
// UsageError naming what is wrong and where.
std::array<double, 3> live_device_frame(const std::string &path);

// "" when a device reporting frame {a, b, m} is the --device file's frame
// (within the 1 mm a calibration's frame is held to), else why not.
std::string live_frame_mismatch(const std::string &path, const std::array<double, 3> &file,
                                const std::array<double, 3> &device);

// `cdm record`'s --live, --live-every, --target-mm, --stable, --next and
// --device (each but --live needs --live).
void add_live_options(CLI::App *record, LiveOptions &o);

// What the analysis knows of the session.
struct LiveSession {
    std::vector<std::array<double, 3>> positions; // every position of the session, in its order (jig frame, mm)
    int samples = 100;                            // per position, for the planner
    int holes = 25;                               // the plate's
    double pitch_mm = 5;
    std::vector<double> heights_mm;
};

class LiveJig {
public:
    // `wait`: the reader waits for each update (an unpaced source).
    LiveJig(const LiveOptions &o, LiveSession s, bool wait);
    ~LiveJig();
    LiveJig(const LiveJig &) = delete;
    LiveJig &operator=(const LiveJig &) = delete;

    // Main thread, once the device is open: the device's nominal geometry
    // (used when LiveOptions::device is empty); updates start then. False
    // + err when the working directory or the device JSON cannot be made.
    bool start(double a_mm, double b_mm, double m_mm, std::string &err);
    // The reader's thread: the session's position `index` (into
    // LiveSession::positions) kept, with its samples (l1..l4, mm) and their
    // times (s). True when the analysis asks the session to stop.
    bool add(size_t index, int point, const double ref[3], const std::vector<std::array<double, 4>> &rows,
             const std::vector<double> &t_s);
    bool stop_requested() const;
    // Lines for the person at the bench, in order; each returned once.
    std::vector<std::string> take_messages();
    // Ends the thread (an update under way, or asked for and not begun,
    // completes first; no advice is planned after this) and returns
    // {"updates": [...], "every", "target_mm", "stable", "stopped" (the
    // analysis ended the session), "model", "predicted_radius95_mm"} (the
    // last update's).
    nlohmann::json finish();

private:
    struct Position {
        size_t index; // into LiveSession::positions
        int point;
        std::array<double, 3> ref;
        std::vector<std::array<double, 4>> rows;
        std::vector<double> t_s;
    };
    void run();
    nlohmann::json update(const std::vector<std::shared_ptr<const Position>> &data);
    bool write_snapshot(const std::vector<std::shared_ptr<const Position>> &data, std::string &err) const;
    void judge(nlohmann::json &u);
    void advise(const std::vector<std::shared_ptr<const Position>> &data, nlohmann::json &u) const;

    LiveOptions o_;
    LiveSession s_;
    bool wait_;
    std::string dir_, device_json_;
    mutable std::mutex mu_;
    std::condition_variable cv_;
    std::vector<std::shared_ptr<const Position>> data_;
    size_t requested_ = 0, done_ = 0; // positions in the newest update asked for, and in the last one made
    bool started_ = false, quit_ = false, stop_ = false;
    std::vector<std::string> messages_;
    nlohmann::json updates_ = nlohmann::json::array();
    std::vector<std::string> last_model_;
    int same_ = 0;
    std::thread thread_;
};

} // namespace cdm::cli

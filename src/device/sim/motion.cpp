#include "device/sim/motion.h"

#include "jig/errors.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace cdm::sim {

namespace {
constexpr double kTwoPi = 6.283185307179586;

// A sum of three sinusoids with random frequencies and phases, scaled so that
// |f(t)| <= 1: smooth (every derivative bounded), never periodic over a
// session, cheap to evaluate at any t without state.
struct Wander {
    double f[3], ph[3], amp[3];
    Wander(std::mt19937_64 &rng, double fmin, double fmax) {
        std::uniform_real_distribution<double> uf(fmin, fmax), up(0, kTwoPi), ua(0.3, 1.0);
        double sum = 0;
        for (int i = 0; i < 3; ++i) {
            f[i] = uf(rng);
            ph[i] = up(rng);
            amp[i] = ua(rng);
            sum += amp[i];
        }
        for (double &a : amp) a /= sum;
    }
    double operator()(double t) const {
        double v = 0;
        for (int i = 0; i < 3; ++i) v += amp[i] * std::sin(kTwoPi * f[i] * t + ph[i]);
        return v;
    }
};

class RandomMotion final : public Motion {
public:
    RandomMotion(uint64_t seed, double grip_open) : rng_(seed), grip_open_(grip_open) {
        // Hand motion lives below ~0.5 Hz; orientation a little slower.
        for (auto &w : pos_) w.emplace_back(rng_, 0.05, 0.4);
        for (auto &w : rot_) w.emplace_back(rng_, 0.03, 0.2);
        jaw_.emplace_back(rng_, 0.1, 0.5);
        clutch_.emplace_back(rng_, 0.02, 0.1);
    }
    bool at(uint64_t, double t, HandState &s) override {
        s.p[0] = 50.0 + 20.0 * pos_[0][0](t);
        s.p[1] = 60.0 * pos_[1][0](t);
        s.p[2] = 60.0 * pos_[2][0](t);
        quat_from_rpy(0.6 * rot_[0][0](t), 0.6 * rot_[1][0](t), 0.6 * rot_[2][0](t), s.q);
        s.jaw_rad = grip_open_ * (0.5 + 0.5 * jaw_[0](t));
        // The clutch is held while a slow wander is near its peak: a few
        // presses a minute, each lasting about a second.
        s.buttons = clutch_[0](t) > 0.75 ? 1u : 0u;
        s.jig_point = -1;
        return true;
    }

private:
    std::mt19937_64 rng_;
    double grip_open_;
    std::vector<Wander> pos_[3], rot_[3], jaw_, clutch_;
};

class StillMotion final : public Motion {
public:
    bool at(uint64_t, double, HandState &s) override {
        s = HandState{};
        return true;
    }
};

class CircleMotion final : public Motion {
public:
    explicit CircleMotion(double grip_open) : grip_open_(grip_open) {}
    bool at(uint64_t, double t, HandState &s) override {
        const double w = kTwoPi * 0.25 * t;
        s.p[0] = 50.0;
        s.p[1] = 40.0 * std::cos(w);
        s.p[2] = 40.0 * std::sin(w);
        quat_from_rpy(0, 0, 0.3 * std::sin(w), s.q);
        s.jaw_rad = grip_open_ * (0.5 + 0.5 * std::sin(2 * w));
        s.buttons = 0;
        s.jig_point = -1;
        return true;
    }

private:
    double grip_open_;
};

class JigMotion final : public Motion {
public:
    JigMotion(const ModelPtr &truth, const JigMotionOptions &o) : o_(o), plan_(make_jig_plan(o.plan)) {
        JigErrorOptions je;
        je.hole_mm = o.tolerance_mm;
        je.fixture_mm = o.tolerance_mm;
        je.seed = o.seed;
        const auto where = jig_true_positions(plan_, o.plan.n, je);
        if (o.visits.empty())
            for (size_t k = 0; k < plan_.size(); ++k) visits_.push_back({k, o.plan.samples});
        else
            visits_ = o.visits;
        // Where each visit's block of reports (transit, then its samples) starts.
        start_.push_back(0);
        for (const PlannedVisit &v : visits_) start_.push_back(start_.back() + uint64_t(o.transit) + uint64_t(v.samples));
        truth_.resize(visits_.size() * 3);
        for (size_t k = 0; k < visits_.size(); ++k) truth->jig_to_device(where[visits_[k].index].data(), &truth_[3 * k]);
    }
    bool at(uint64_t index, double, HandState &s) override {
        s = HandState{};
        if (index >= start_.back()) {
            // A short rest with MARK released after the last dwell, then the
            // end: a recorder sees the last dwell close like every other.
            if (index >= start_.back() + uint64_t(o_.transit)) return false;
            const double *p = &truth_[3 * (visits_.size() - 1)];
            for (int i = 0; i < 3; ++i) s.p[i] = p[i];
            return true;
        }
        const size_t k = size_t(std::upper_bound(start_.begin(), start_.end(), index) - start_.begin()) - 1;
        const uint64_t r = index - start_[k];
        const double *to = &truth_[3 * k];
        if (r < uint64_t(o_.transit)) {
            const double *from = k == 0 ? to : &truth_[3 * (k - 1)];
            const double f = double(r + 1) / double(o_.transit + 1);
            for (int i = 0; i < 3; ++i) s.p[i] = from[i] + f * (to[i] - from[i]);
            return true;
        }
        for (int i = 0; i < 3; ++i) s.p[i] = to[i];
        s.buttons = 1u << 2; // MARK: seated
        s.jig_point = plan_[visits_[k].index].point;
        return true;
    }

private:
    JigMotionOptions o_;
    std::vector<JigPosition> plan_;
    std::vector<PlannedVisit> visits_;
    std::vector<uint64_t> start_; // visits_.size() + 1 entries
    std::vector<double> truth_;   // each visit's true position, device frame
};
} // namespace

void quat_mul(const double a[4], const double b[4], double r[4]) {
    const double w = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    const double x = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    const double y = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    const double z = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
    r[0] = w;
    r[1] = x;
    r[2] = y;
    r[3] = z;
}

void quat_from_rpy(double roll, double pitch, double yaw, double q[4]) {
    const double cr = std::cos(roll / 2), sr = std::sin(roll / 2);
    const double cp = std::cos(pitch / 2), sp = std::sin(pitch / 2);
    const double cy = std::cos(yaw / 2), sy = std::sin(yaw / 2);
    q[0] = cr * cp * cy + sr * sp * sy;
    q[1] = sr * cp * cy - cr * sp * sy;
    q[2] = cr * sp * cy + sr * cp * sy;
    q[3] = cr * cp * sy - sr * sp * cy;
}

std::unique_ptr<Motion> make_random_motion(uint64_t seed, double grip_open_rad) {
    return std::make_unique<RandomMotion>(seed, grip_open_rad);
}
std::unique_ptr<Motion> make_still_motion() { return std::make_unique<StillMotion>(); }
std::unique_ptr<Motion> make_circle_motion(double grip_open_rad) {
    return std::make_unique<CircleMotion>(grip_open_rad);
}
std::unique_ptr<Motion> make_jig_motion(const ModelPtr &truth, const JigMotionOptions &o) {
    return std::make_unique<JigMotion>(truth, o);
}

} // namespace cdm::sim

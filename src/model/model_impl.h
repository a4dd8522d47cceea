// Model internals. Private to src/model: the fit goes through
// model/evaluator.h and the public accessors.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "model/effect.h"
#include "model/kernel.h"
#include "model/model.h"
#include "model/user_effect.h"

namespace cdm {

struct EffectInst {
    EffectDescPtr desc;
    std::vector<double> p;
};

// Built from the model's effects (refresh): where each active built-in's
// parameters are, and where each cable's parameter block comes from.
struct ModelLayout {
    std::array<int, kBuiltinCount> idx;      // model effect index of each built-in, -1 when off
    CableLayout cable;                        // slot layout of a cable's parameter block
    std::array<std::array<int, kMaxCableSlots>, 4> slot_effect{}; // model effect index of each slot
    std::array<std::array<int, kMaxCableSlots>, 4> slot_param{};  // parameter index of each slot
    bool has_user = false;
    bool has_geom = false;        // a user effect with apply_geom (since 1.2)
    bool has_path_user = false;   // a user effect on the path (CDM_EFFECT_STAGE_PATH)
    bool reading_effects = false; // anything besides Jig and Position stages

};
// descs: the model's effects in order.
ModelLayout build_layout(const std::vector<const EffectDesc *> &descs);

struct Model::Impl {
    DeviceGeometry g;
    std::vector<EffectInst> effects; // in the order of application
    ModelLayout lay;

    void refresh();
    const double *params(int builtin) const {
        return lay.idx[builtin] >= 0 ? effects[size_t(lay.idx[builtin])].p.data() : nullptr;
    }
    // Cable i's parameter block, converted to T (constants for AD).
    template <class T> void gather(int i, T *q) const {
        for (int s = 0; s < lay.cable.nslots; ++s)
            q[s] = T(effects[size_t(lay.slot_effect[i][s])].p[size_t(lay.slot_param[i][s])]);
    }
    EffectParams<double> whole_params() const {
        EffectParams<double> p{};
        for (int id = 0; id < kBuiltinCount; ++id) p[size_t(id)] = params(id);
        return p;
    }
    // Readings of the built-in stages, then user effects. 0, or -1 when a
    // user effect's apply fails (its name in *who).
    int builtin_readings(const Sample<double> &s, double out[4]) const;
    int apply_user(const double p[3], double readings[4], std::string *who) const;
    // With a geometry-aware user effect (lay.has_geom): the four cables'
    // lengths after the Path stage and their frames at s; the Transfer
    // stage on given lengths; and the readings through every stage, the
    // user effects at theirs (0, or -1 naming the failing effect in *who).
    // No allocation: the driver's forward kinematics calls these.
    void path_frame(const Sample<double> &s, double len[4], CableFrame &f) const;
    void transfer_of(const Sample<double> &s, const double len[4], double out[4]) const;
    int readings_geom(const Sample<double> &s, double out[4], std::string *who) const;
};

// The forward kinematics' pieces (model_position.cpp), shared by the
// per-position solve and the batched one (position_batch.cpp) so that both
// do the same arithmetic: the position step of the readings' central
// differences through user effects, the Gauss-Newton limits, the start when
// the nominal spheres do not meet, one Gauss-Newton step (x += the
// least-squares step on lengths - y; -1 when anything is not finite, 1 when
// the step's norm is under kFkTolerance, else 0) and the Position-stage
// corrections (with their 3x3 Jacobian when D is not null; false when a
// Position-stage effect has more parameters than its stack buffer holds).
constexpr double kFkPositionStep = 1e-4; // mm
constexpr int kFkIterations = 30;
constexpr double kFkTolerance = 1e-9; // mm
void fk_fallback_start(const DeviceGeometry &g, const double lengths[4], double x[3]);
int fk_step(const double lengths[4], const Eigen::Matrix<double, 4, 1> &y, const Eigen::Matrix<double, 4, 3> &J,
            double x[3]);
bool fk_correct(const Model::Impl &I, double x[3], Eigen::Matrix3d *D);

} // namespace cdm

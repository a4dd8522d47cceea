// The effect catalogue: what a physical effect is to the model (its
// parameters, units, typical magnitude, where it acts), and the registry that
// lists the built-in ones (effects/list.h, one file per effect) and the ones a
// user registers at run time (C callback, plugin, Python).
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cdm/cdm.h"

namespace cdm {

// Where an effect acts. The order of the stages is the order of evaluation.
enum class Stage {
    Jig,      // maps the jig's reference positions into the device frame
    Geometry, // moves anchors or holder attachment points
    Path,     // how the cable runs from its exit to the holder
    Transfer, // pot transfer curve: pulled-out length -> reading
    User,     // user-defined, on the readings (cdm_effect_def)
    Position  // corrects the estimated position (the seed's ellipsoid)
};

// What the diagnosis may do with a parameter beyond fitting it from its
// initial value: declared by the effect, never read from its name.
enum class ParamRole : std::uint8_t {
    Plain,
    // A period in the cable's length (mm): the residual's periodogram seeds
    // it, and a fit searches along its profile (a sine's period has many
    // local minima).
    LengthPeriod
};

struct ParamDesc {
    std::string name;
    std::string unit;
    double scale;       // typical magnitude: conditioning and the weak prior
    double lower, upper;
    double init;        // value when the effect is switched on
    double rand_lo, rand_hi; // |value| drawn in [lo, hi] with a random sign (simulator)
    bool signed_random = true;
    // The physically plausible range of the fitted value (the effect's own
    // physics, wider than the typical magnitude): a fit that needs a value
    // outside it is using the effect as a stand-in for something else. The
    // words say what such a value would mean ("something lengthens the
    // reading as the cable lengthens"). Default: the fit's bounds, no claim.
    double plausible_lo = -INFINITY, plausible_hi = INFINITY;
    std::string below_means = std::string(), above_means = std::string();
    ParamRole role = ParamRole::Plain;
    ParamDesc as(ParamRole r) const {
        ParamDesc p = *this;
        p.role = r;
        return p;
    }
    ParamDesc plausible(double lo, double hi, std::string below = "", std::string above = "") const {
        ParamDesc p = *this;
        p.plausible_lo = lo;
        p.plausible_hi = hi;
        p.below_means = std::move(below);
        p.above_means = std::move(above);
        return p;
    }
};

// A geometric effect whose parameters are one 3-D displacement (x, y, z)
// per cable's point (an anchor, a holder attachment): a machining error
// moves each point on its own; a pattern shared by the four points (a
// common x shift, all points radially in or out) is a deformation, or the
// effect standing in for a smooth effect it is not (calib's stand-in test).
struct PointDisplacements {
    bool present = false;
    bool anchors = false; // the anchors (true) or the holder's points (false)
};

// The most parameters a user effect may have (cdm_effect_register refuses
// more): the evaluator's per-call buffers are sized by it.
constexpr int kMaxUserParams = 64;

// What an effect's advice may use: its fitted values and their standard
// errors, and the session's span of acquisition time (hours).
struct AdviceIn {
    const std::vector<double> &value, &std;
    double t0_h, t1_h;
};

struct EffectDesc {
    std::string name;
    std::string doc;       // the physics in one paragraph, with the typical magnitude
    Stage stage;
    int builtin_id;        // index in CDM_BUILTIN_EFFECTS (effects/list.h), or -1 for a user effect
    std::vector<ParamDesc> params;
    PointDisplacements points = PointDisplacements(); // the parameters are 4 points' displacements
    // What a fitted value means for the user's practice, in a sentence that
    // starts with a space ("" when the fit says nothing beyond its numbers):
    // the diagnosis appends it to its advice.
    std::string (*advice)(const AdviceIn &) = nullptr;
    // user effects only: at least one of apply, apply_batch and apply_geom
    // (cdm.h says which is called when)
    cdm_effect_apply_fn apply = nullptr;
    cdm_effect_apply_batch_fn apply_batch = nullptr;
    cdm_effect_apply_geom_fn apply_geom = nullptr; // since 1.2: the only one called when given
    void *user = nullptr;
    // since 1.2: a user effect on the cable's length before the pot's
    // transfer (CDM_EFFECT_STAGE_PATH) rather than on the readings. Its
    // Stage stays User (it is a user effect to the fit and the diagnosis);
    // the kernel's callers apply it between the Path and Transfer stages.
    bool on_path = false;
    std::string origin = "";      // where it comes from (a plugin's path, "python:module"), or ""
    std::string fingerprint = ""; // effect_fingerprint(*this), set at registration
    bool is_user() const { return builtin_id < 0; }
    // At one position: apply, or apply_batch on one row when the effect has
    // only that (no allocation either way: the haptic path calls this).
    int apply_one(const double *params, const double position_mm[3], double readings_mm[4]) const {
        return apply ? apply(user, params, position_mm, readings_mm)
                     : apply_batch(user, params, 1, position_mm, readings_mm);
    }
};

using EffectDescPtr = std::shared_ptr<const EffectDesc>;

// The registry. Built-ins first (in catalogue order), then user effects in
// registration order. Thread-safe.
EffectDescPtr find_effect(const std::string &name);
std::vector<EffectDescPtr> all_effects();
// The catalogue the diagnosis ranks: every physical built-in (not the
// ellipsoid) plus every user effect.
std::vector<EffectDescPtr> candidate_effects();
int register_user_effect(const cdm_effect_def *def, std::string &err);
// The origin given to the effects registered on this thread until it is
// reset with nullptr (cdm_effect_load_plugin: the plugin's path, whatever
// the definition says).
void set_registering_origin(const char *origin);
// 16 hex digits of the FNV-1a 64-bit hash of what a calibration's values of
// the effect mean: its stage, then each parameter's name and unit.
std::string effect_fingerprint(const EffectDesc &d);
int unregister_user_effect(const std::string &name, std::string &err);

// The catalogue as a Markdown table (docs/calibration.md carries a copy that
// a test keeps equal): one row per built-in, in the order of application.
std::string catalogue_markdown();
// The stages in order with the built-ins of each, for docs/effects.md.
std::string stages_markdown();

} // namespace cdm

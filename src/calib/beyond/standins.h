// Stand-ins: a fitted effect that brings the residual to the noise floor
// with values its own physics does not allow is not the explanation; it is
// standing in for an effect the model lacks. Two signs, each declared by the
// effect in its own file (model/effect.h), none matched by name here:
//  - range: a parameter outside its plausible range (ParamDesc::plausible)
//    by more than kStandInSe standard errors, e.g. cable_stretch fitted as a
//    compression;
//  - pattern: an effect whose parameters are the four points' displacements
//    (EffectDesc::points) moving them together in the frame's symmetric
//    modes (a common x shift, all points radially in or out in y or in z)
//    far more than independent machining errors of each point would: a
//    deformation, or a smooth effect borrowed from the geometry.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/fit/fit.h"
#include "model/model.h"

namespace cdm {
namespace diag {

// A value is called outside its plausible range only when the range is
// more than this many of its standard errors away (a value at the edge,
// within its noise, is not evidence).
constexpr double kStandInSe = 3.0;

struct StandIn {
    std::string effect;
    std::string kind; // "range" or "pattern"
    std::string words; // the sentence the verdict gives
    nlohmann::json detail;
};

// The stand-ins among m's fitted effects (rep: m's fit, for the standard
// errors; none are known when rep.std is empty, and a range is then judged
// on the value alone).
std::vector<StandIn> find_stand_ins(const Model &m, const FitReport &rep);

nlohmann::json stand_ins_json(const std::vector<StandIn> &s);
// "cable_stretch's s0 = -2.9e-04 ... ; holder_geometry's four points ...":
// the stand-ins' sentences joined, "" when none.
std::string stand_ins_words(const std::vector<StandIn> &s);
// The effects named in s, once each, in s's order.
std::vector<std::string> stand_in_effects(const std::vector<StandIn> &s);

} // namespace diag
} // namespace cdm

// Beyond every catalogued effect: which physically meaningful term, added to
// each cable's reading, explains what a model leaves. A library of per-cable
// terms in the variables effects depend on (the cable's chord length L, its
// direction u = (u_x, u_y, u_z) in the device frame, products of the two,
// the acquisition time, the fixture height, the direction the cable last
// moved to reach the position, and a period in length when the periodogram
// found one), each with one coefficient common to the four cables; a sparse
// regression (forward stepwise, orthogonal matching pursuit) picks the
// fewest terms, each fitted jointly with the model (linearised: the model's
// whitened Jacobian and the fixture heights' offsets projected out, so a
// term the model can already make gains nothing), each kept only when its
// likelihood ratio passes kFindingLevel (Bonferroni over the library) and it
// lowers the BIC. The result is a hypothesis with a shape ("c L^3 (1 -
// u_z^2): the shape of cable sag under gravity along z"), the error it
// reaches and its BIC against the model it is compared with; never a
// recommended model by itself (the user writes the effect: docs/effects.md).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/search/context.h"

namespace cdm {
namespace diag {

// At most this many terms: a sparse answer a person can read as physics.
constexpr int kMaxDiscoveredTerms = 3;

struct Discovery {
    bool found = false;
    std::vector<std::string> terms;
    std::vector<double> coef, se;
    double dchi2 = 0;       // chi-square the terms gain over `base` (linearised joint refit)
    double bic_vs_base = 0; // BIC change against base alone
    double bic_vs_other = NAN; // BIC change against `other` (the stand-ins' model), when given
    // The share of the leading term's whitened column that `other`'s
    // Jacobian cannot make: near 0 when the term is a special case of its
    // effects (a drift common to the cables is pot_drift's), when given.
    double outside_other = NAN;
    Eval E;                 // base + terms after one joint Gauss-Newton step, on the data
    nlohmann::json json = nullptr;
    std::string words;      // the verdict's sentence ("" when nothing was found)
    std::string other_name; // what bic_vs_other compares with, in words
    // Where the terms do not compete: which variable the residual follows,
    // as a pointer for the user ("" when nothing was found).
    std::string lead_words;
    // Worth a reader's time: no model to compare with, or the terms' model
    // within the alternatives' margin (10) of it or better. A term that
    // loses to the catalogue's model by more is in the JSON only.
    bool competitive() const { return found && !(bic_vs_other > 10.0); }
};

// base: a fitted model (base_rep its fit) whose readings' residual is
// searched; other (may be null): a fitted model to compare with (the
// recommended one, with its stand-ins; other_rep its fit). Both are weighed
// as base weighs the data (ctx.fo with weigh_with = base). False + err only
// when a user effect fails.
// other_name: how the words call `other` ("the stand-ins"). out:
// default-constructed (it is filled, not reset).
bool discover_terms(const DiagContext &ctx, const Model &base, const FitReport &base_rep, const Model *other,
                    const FitReport *other_rep, const std::string &other_name, Discovery &out, std::string &err);

} // namespace diag
} // namespace cdm

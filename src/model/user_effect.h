// Calling a geometry-aware user effect (cdm_effect_def.apply_geom, since
// 1.2): the cable frames its context is made of, and the one function that
// builds the context and makes the call. Shared by the model's readings
// (model.cpp, position_batch.cpp) and the fit's evaluator. Private to
// src/model.
#pragma once

#include <cstddef>

#include "model/effect.h"
#include "model/kernel.h"

namespace cdm {

// The four cables of one position, as the context gives them: anchors,
// holder points and unit vectors 4 x 3 each, chords 4 (device frame, mm).
struct CableFrame {
    double anchor[12], holder[12], unit[12], chord[4];
    void set(int cable, const CablePoints &p) {
        for (int k = 0; k < 3; ++k) {
            anchor[3 * cable + k] = p.anchor[k];
            holder[3 * cable + k] = p.holder[k];
            unit[3 * cable + k] = p.unit[k];
        }
        chord[cable] = p.chord;
    }
};
static_assert(sizeof(CableFrame) == 40 * sizeof(double), "CableFrame: arrays without padding between them");

// n rows of a call: positions n x 3, times n, and the frames (n of them,
// contiguous), which only a geometry-aware effect reads (may be null for
// the others).
struct UserRows {
    size_t n;
    const double *P;
    const double *t_s;
    const CableFrame *frame;
};

// Calls user effect d with parameters prm on the rows, values (n x 4) in
// place: apply_geom with the context when it has one, else apply_batch over
// the rows, else apply on each row. Returns the callback's status (the
// first non-zero one). Allocates nothing for n = 1; for n > 1 the context's
// frame arrays are gathered into `scratch` (3 x 12 n + 4 n doubles).
int call_user_effect(const EffectDesc &d, const double *prm, const UserRows &rows, double *values,
                     double *scratch = nullptr);
// The scratch call_user_effect needs for n rows of a geometry-aware effect.
constexpr size_t user_scratch_size(size_t n) { return n > 1 ? 40 * n : 0; }

} // namespace cdm

// See user_effect.h.
#include "model/user_effect.h"

#include <algorithm>

namespace cdm {

int call_user_effect(const EffectDesc &d, const double *prm, const UserRows &rows, double *values,
                     double *scratch) {
    const size_t n = rows.n;
    if (n == 0) return 0;
    if (!d.apply_geom) {
        if (d.apply_batch && (n > 1 || !d.apply)) return d.apply_batch(d.user, prm, n, rows.P, values);
        for (size_t r = 0; r < n; ++r)
            if (const int rc = d.apply(d.user, prm, rows.P + 3 * r, values + 4 * r)) return rc;
        return 0;
    }
    cdm_effect_context c{};
    c.struct_size = sizeof c;
    c.stage = d.on_path ? CDM_EFFECT_STAGE_PATH : CDM_EFFECT_STAGE_READING;
    c.n = n;
    c.positions_mm = rows.P;
    c.t_s = rows.t_s;
    if (n == 1) {
        // One frame's arrays are already the context's shape: no copy.
        c.anchors_mm = rows.frame->anchor;
        c.holders_mm = rows.frame->holder;
        c.unit = rows.frame->unit;
        c.chord_mm = rows.frame->chord;
    } else {
        // n frames side by side into four n-row arrays.
        double *A = scratch, *H = A + 12 * n, *U = H + 12 * n, *C = U + 12 * n;
        for (size_t r = 0; r < n; ++r) {
            const CableFrame &f = rows.frame[r];
            std::copy(f.anchor, f.anchor + 12, A + 12 * r);
            std::copy(f.holder, f.holder + 12, H + 12 * r);
            std::copy(f.unit, f.unit + 12, U + 12 * r);
            std::copy(f.chord, f.chord + 4, C + 4 * r);
        }
        c.anchors_mm = A;
        c.holders_mm = H;
        c.unit = U;
        c.chord_mm = C;
    }
    return d.apply_geom(d.user, prm, n, &c, values);
}

} // namespace cdm

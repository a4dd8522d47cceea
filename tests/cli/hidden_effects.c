/* Physical effects outside cdm's catalogue, as a plugin: the simulator's
 * truth for the tests of the diagnosis beyond the catalogue
 * (test_beyond_catalogue.py). They are the hidden physics, not effects a
 * user would write (those see the geometry through the callback): so the
 * nominal frame (a = b = 150 mm, m = 30 mm, docs/protocol.md's numbering)
 * is written out here, as a simulator of one particular device would.
 *
 *   hidden_sag          the pot reads the catenary's arc, longer than the
 *                       chord by c L^3 (1 - u_z^2), gravity along z (an
 *                       upright frame): depends on the length and the
 *                       inclination to gravity.
 *   hidden_side_guide   a guide beside each exit point, along y: the cable
 *                       rubs over it by k u_y^2 (mm): depends on the
 *                       direction alone.
 *   hidden_holder_weight the grip's weight, along z, shared by the cables:
 *                       each stretches by w L u_z: depends on the length
 *                       times the direction.
 *   hidden_worn_spot    a worn band of the pots' tracks: the reading is off
 *                       by A exp(-(L - L0)^2 / (2 s^2)) near L0: depends on
 *                       the length alone, and no polynomial of it.
 *   hidden_warmup       the cables warm after a cold start and lengthen by
 *                       a L (1 - exp(-t / tau)): depends on the time and
 *                       the length (through the geometry API's t_s).
 */
#define CDM_EXPERIMENTAL
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "cdm/cdm.h"

static const double kA = 150.0, kB = 150.0, kM = 30.0;
static const double kSy[4] = {+1, +1, -1, -1}, kSz[4] = {-1, +1, -1, +1};

/* Cable i's chord vector (anchor to holder corner) and length. */
static double chord(int i, const double p[3], double u[3]) {
    const double d[3] = {p[0], p[1] + kSy[i] * (kM / 2 - kA), p[2] + kSz[i] * (kM / 2 - kB)};
    const double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; ++k) u[k] = d[k] / L;
    return L;
}

static int sag(void *user, const double *q, const double p[3], double r[4]) {
    (void)user;
    for (int i = 0; i < 4; ++i) {
        double u[3];
        const double L = chord(i, p, u);
        r[i] += q[0] * L * L * L * (1 - u[2] * u[2]);
    }
    return 0;
}

static int side_guide(void *user, const double *q, const double p[3], double r[4]) {
    (void)user;
    for (int i = 0; i < 4; ++i) {
        double u[3];
        chord(i, p, u);
        r[i] += q[0] * u[1] * u[1];
    }
    return 0;
}

static int holder_weight(void *user, const double *q, const double p[3], double r[4]) {
    (void)user;
    for (int i = 0; i < 4; ++i) {
        double u[3];
        const double L = chord(i, p, u);
        r[i] += q[0] * L * u[2];
    }
    return 0;
}

static int worn_spot(void *user, const double *q, const double p[3], double r[4]) {
    (void)user;
    for (int i = 0; i < 4; ++i) {
        double u[3];
        const double L = chord(i, p, u);
        r[i] += q[0] * exp(-(L - q[1]) * (L - q[1]) / (2 * q[2] * q[2]));
    }
    return 0;
}

static int warmup(void *user, const double *q, size_t n, const cdm_effect_context *ctx, double *values) {
    (void)user;
    for (size_t j = 0; j < n; ++j)
        for (int i = 0; i < 4; ++i)
            values[4 * j + (size_t)i] += q[0] * ctx->chord_mm[4 * j + (size_t)i] * (1 - exp(-ctx->t_s[j] / q[1]));
    return 0;
}

int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *));
int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *)) {
    static const char *const n_sag[] = {"c"}, *const n_guide[] = {"k"}, *const n_weight[] = {"w"},
                             *const n_spot[] = {"amplitude", "centre", "width"};
    static const double s_sag[] = {1e-8}, s_guide[] = {0.1}, s_weight[] = {1e-3}, s_spot[] = {0.1, 10, 5};
    static const double lo_spot[] = {-5, 100, 1}, hi_spot[] = {5, 400, 100};
    cdm_effect_def defs[4] = {{0}};
    const char *names[4] = {"hidden_sag", "hidden_side_guide", "hidden_holder_weight", "hidden_worn_spot"};
    const char *docs[4] = {"cable sag under gravity along z (test truth)", "a guide along y at each exit (test truth)",
                           "the grip's weight along z (test truth)", "a worn band of the pots' tracks (test truth)"};
    const char *const *pn[4] = {n_sag, n_guide, n_weight, n_spot};
    const double *ps[4] = {s_sag, s_guide, s_weight, s_spot};
    const uint32_t np[4] = {1, 1, 1, 3};
    const cdm_effect_apply_fn fn[4] = {sag, side_guide, holder_weight, worn_spot};
    for (int k = 0; k < 4; ++k) {
        defs[k].struct_size = sizeof(cdm_effect_def);
        defs[k].n_params = np[k];
        defs[k].name = names[k];
        defs[k].doc = docs[k];
        defs[k].param_names = pn[k];
        defs[k].param_scale = ps[k];
        defs[k].apply = fn[k];
    }
    defs[3].lower = lo_spot;
    defs[3].upper = hi_spot;
    for (int k = 0; k < 4; ++k) {
        const int rc = register_fn(&defs[k]);
        if (rc != CDM_OK) return rc;
    }
    static const char *const n_warm[] = {"a", "tau_s"};
    static const double s_warm[] = {1e-4, 600}, lo_warm[] = {-1e-2, 10}, hi_warm[] = {1e-2, 1e5};
    cdm_effect_def w = {0};
    w.struct_size = sizeof w;
    w.n_params = 2;
    w.name = "hidden_warmup";
    w.doc = "the cables warming after a cold start (test truth)";
    w.param_names = n_warm;
    w.param_scale = s_warm;
    w.lower = lo_warm;
    w.upper = hi_warm;
    w.apply_geom = warmup;
    w.stage = CDM_EFFECT_STAGE_READING;
    return register_fn(&w);
}

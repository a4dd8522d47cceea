/* Cable sag under gravity, a user effect on the cable's path (a plugin).
 *
 * A cable of weight w per length under tension T between two points a chord
 * L apart hangs in a catenary; for a shallow one the pot counts its arc,
 * longer than the chord by
 *     dL = w_perp^2 L^3 / (24 T^2),
 * w_perp the weight per length across the cable (the parabolic
 * approximation of the catenary, first order in (w L / T)^2). With u the
 * unit vector along the cable and g that of gravity, w_perp^2 = w^2 (1 -
 * (u.g)^2), so
 *     dL = c L^3 (1 - (u.g)^2),  c = w^2 / (24 T^2)  (1/mm^2: w in N/mm, T in N).
 * A cable of 10 g/m under 0.1 N has c ~ 4e-8 /mm^2: 0.3 mm on a 200 mm
 * horizontal cable; a vertical one does not sag.
 *
 * The geometry comes from the model: the callback reads each cable's chord
 * and direction from the context (the anchors after anchor_position and
 * the holder points after holder_geometry, at the values the fit has
 * reached), so nothing here knows the frame's size or the cables'
 * numbering. The one assumption is the frame's orientation: upright, its
 * +z axis up (gravity along -z in the device frame); a frame mounted
 * otherwise changes kGravity.
 *
 * It acts on the path: the pot's transfer (cable_gain, cable_stretch, ...)
 * applies to the sagging length, as it does to the real cable.
 *
 *     cc -shared -fPIC -o cable_sag.so cable_sag.c
 *     cdm calib diagnose jig.csv --plugin ./cable_sag.so --effects cable_sag
 */
#define CDM_EXPERIMENTAL
#include <cdm/cdm.h>

#include <stddef.h>

/* Gravity's unit vector in the device frame: an upright frame, +z up. */
static const double kGravity[3] = {0.0, 0.0, -1.0};

/* n positions at once, each with its four cables: values (n x 4) are the
 * cables' lengths so far (mm); add each one's sag. Smooth in c and in the
 * position (the chord and direction move smoothly with it). */
static int cable_sag(void *user, const double *params, size_t n, const cdm_effect_context *ctx, double *values) {
    (void)user;
    const double c = params[0];
    for (size_t i = 0; i < n; ++i)
        for (size_t k = 0; k < 4; ++k) {
            const double *u = ctx->unit + 3 * (4 * i + k);
            const double L = ctx->chord_mm[4 * i + k];
            const double ug = u[0] * kGravity[0] + u[1] * kGravity[1] + u[2] * kGravity[2];
            values[4 * i + k] += c * L * L * L * (1.0 - ug * ug);
        }
    return 0;
}

/* The plugin's one entry point (the library looks it up by name). */
__attribute__((visibility("default"))) int cdm_plugin_init(int (*reg)(const cdm_effect_def *));
__attribute__((visibility("default"))) int cdm_plugin_init(int (*reg)(const cdm_effect_def *)) {
    static const char *const names[] = {"c_per_mm2"};
    static const char *const units[] = {"1/mm^2"};
    /* Typical 1e-8 /mm^2 (0.08 mm on a 200 mm horizontal cable); no sag
     * below 0; 1e-6 would be a 1 mm sag on 100 mm, far past shallow. */
    static const double scale[] = {1e-8}, lower[] = {0.0}, upper[] = {1e-6}, initial[] = {0.0};
    cdm_effect_def d = {0};
    d.struct_size = sizeof d;
    d.n_params = 1;
    d.name = "cable_sag";
    d.doc = "Cable sag under gravity: each cable's arc is longer than its chord L by c*L^3*(1 - (u.g)^2), "
            "u the cable's direction, g gravity's (-z: an upright frame), c = w^2/(24 T^2) (w weight per "
            "length, T tension), 1/mm^2. Acts on the path, before the pot's transfer. Typical: 1e-9..1e-7.";
    d.param_names = names;
    d.param_units = units;
    d.param_scale = scale;
    d.lower = lower;
    d.upper = upper;
    d.initial = initial;
    d.apply_geom = cable_sag;
    d.stage = CDM_EFFECT_STAGE_PATH;
    return reg(&d);
}

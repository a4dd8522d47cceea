/*
 * A user-defined effect as a plugin: a dip worn into the pots' resistive
 * tracks where the wiper rests most (the cable length at the home position),
 * so every reading in a narrow band of cable length is off. Nothing in the
 * catalogue is local in cable length; docs/calibration.md walks through
 * finding it ("Beyond the catalogue").
 *
 *   cc -shared -fPIC -o worn_spot.so worn_spot.c -lm
 *   cdm calib diagnose jig.csv --device dev.json --plugin ./worn_spot.so --effects worn_spot
 *
 * Three parameters: the dip's depth (mm of reading), its centre and its
 * width (mm of cable). The centre and width enter non-linearly, so they are
 * started from `initial` (cdm_effect_def since 1.1: where the length
 * residual plot shows the dip) and fitted with the depth.
 */
#define CDM_EXPERIMENTAL
#include <cdm/cdm.h>
#include <math.h>

static int worn_spot(void *user, const double *p, const double position_mm[3], double readings_mm[4]) {
    (void)user;
    (void)position_mm;
    if (!(p[2] > 0)) return 1; /* a width must be positive: the fit's bounds keep it so */
    for (int i = 0; i < 4; ++i) {
        const double u = (readings_mm[i] - p[1]) / p[2];
        readings_mm[i] += p[0] * exp(-u * u);
    }
    return 0;
}

__attribute__((visibility("default"))) int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *)) {
    static const char *names[] = {"depth_mm", "centre_mm", "width_mm"};
    static const double scale[] = {0.1, 10.0, 2.0};
    static const double lower[] = {-5.0, 50.0, 1.0};
    static const double upper[] = {5.0, 400.0, 50.0};
    static const double initial[] = {0.0, 178.0, 5.0}; /* read off the length residual plot */
    cdm_effect_def d = {0};
    d.struct_size = sizeof d;
    d.n_params = 3;
    d.name = "worn_spot";
    d.doc = "A dip worn into the pot tracks around one cable length: r += depth * exp(-((L - centre) / width)^2).";
    d.param_names = names;
    d.param_scale = scale;
    d.lower = lower;
    d.upper = upper;
    d.initial = initial;
    d.apply = worn_spot;
    return register_fn(&d);
}

/*
 * A user-defined effect as a plugin: a reading error periodic in the cable's
 * own length, as an eccentric drum or shaft makes (it turns once per drum
 * circumference of cable). docs/calibration.md walks through finding it.
 *
 *   cc -shared -fPIC -o drum_ripple.so drum_ripple.c -lm
 *   cdm calib diagnose jig.csv --device dev.json --plugin ./drum_ripple.so --effects drum_ripple
 *
 * The period is fixed here (the periodogram of the diagnosis found it); the
 * fit finds the sine and cosine amplitudes, common to the four identical pots.
 */
#define CDM_EXPERIMENTAL
#include <cdm/cdm.h>
#include <math.h>

#ifndef DRUM_RIPPLE_PERIOD_MM
#define DRUM_RIPPLE_PERIOD_MM 37.0
#endif

static double period_mm = DRUM_RIPPLE_PERIOD_MM;

static int ripple(void *user, const double *p, const double position_mm[3], double readings_mm[4]) {
    const double P = *(const double *)user;
    (void)position_mm;
    for (int i = 0; i < 4; ++i) {
        const double ph = 2 * M_PI * readings_mm[i] / P;
        readings_mm[i] += p[0] * sin(ph) + p[1] * cos(ph);
    }
    return 0;
}

__attribute__((visibility("default"))) int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *)) {
    static const char *names[] = {"sin_mm", "cos_mm"};
    static const double scale[] = {0.05, 0.05};
    cdm_effect_def d = {0};
    d.struct_size = sizeof d;
    d.n_params = 2;
    d.name = "drum_ripple";
    d.doc = "Reading error periodic in cable length (eccentric drum): r += a sin(2 pi L / P) + b cos(2 pi L / P).";
    d.param_names = names;
    d.param_scale = scale;
    d.apply = ripple;
    d.user = &period_mm;
    return register_fn(&d);
}

#include "calib/simulate.h"

#include <algorithm>
#include <cmath>
#include <random>

namespace cdm {

namespace {
template <class Sink> bool run(const Model &truth, const JigSimOptions &o, Sink sink, std::string &err) {
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<double> g(0.0, 1.0);
    long id = 0;
    const double c = (o.n - 1) / 2.0;
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const double hlo = *std::min_element(o.heights.begin(), o.heights.end());
    const double hhi = *std::max_element(o.heights.begin(), o.heights.end());
    for (double h : o.heights)
        for (int iz = 0; iz < o.n; ++iz)
            for (int iy = 0; iy < o.n; ++iy) {
                double ref[3] = {h, (iy - c) * o.pitch_mm, (iz - c) * o.pitch_mm};
                if (o.scattered) {
                    ref[0] = hlo + (hhi - hlo) * u(rng);
                    ref[1] = (2 * u(rng) - 1) * c * o.pitch_mm;
                    ref[2] = (2 * u(rng) - 1) * c * o.pitch_mm;
                }
                double jig[3];
                for (int k = 0; k < 3; ++k) jig[k] = ref[k] + o.jig_tolerance_mm * g(rng);
                double p[3], L[4];
                truth.jig_to_device(jig, p);
                truth.readings(p, L);
                for (int k = 0; k < 4; ++k)
                    if (!std::isfinite(L[k])) {
                        err = "simulated readings are not finite at point " + std::to_string(id);
                        return false;
                    }
                for (int s = 0; s < o.samples; ++s) {
                    double l[4];
                    for (int k = 0; k < 4; ++k) {
                        l[k] = L[k] + o.noise_mm * g(rng);
                        if (o.quant_mm > 0) l[k] = std::round(l[k] / o.quant_mm) * o.quant_mm;
                    }
                    sink(id, ref, l);
                }
                ++id;
            }
    return true;
}
} // namespace

bool simulate_jig_csv(const Model &truth, const JigSimOptions &o, const std::string &path, std::string &err) {
    std::vector<long> pt;
    std::vector<std::array<double, 3>> ref;
    std::vector<std::array<double, 4>> len;
    if (!run(truth, o,
             [&](long id, const double *r, const double *l) {
                 pt.push_back(id);
                 ref.push_back({r[0], r[1], r[2]});
                 len.push_back({l[0], l[1], l[2], l[3]});
             },
             err))
        return false;
    return write_dataset_csv(path, pt, ref, len, err);
}

bool simulate_jig(const Model &truth, const JigSimOptions &o, Dataset &out, std::string &err) {
    std::string text = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    char buf[256];
    if (!run(truth, o,
             [&](long id, const double *r, const double *l) {
                 std::snprintf(buf, sizeof buf, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", id, r[0], r[1], r[2], l[0],
                               l[1], l[2], l[3]);
                 text += buf;
             },
             err))
        return false;
    return parse_dataset(text, "(simulated)", out, err);
}

} // namespace cdm

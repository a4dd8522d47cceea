// See diag_findings.h.
#include "calib/diag_findings.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Dense>

#include "calib/diag_residual.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {
const char *kAxis[3] = {"x", "y", "z"};
} // namespace

json residual_findings(const std::vector<PreparedPos> &pos, const std::vector<std::array<double, 4>> &lmean,
                       const std::vector<std::array<double, 4>> &lres, const std::vector<std::array<double, 4>> &angle,
                       const Eval &bE, const V3 &jig) {
    const size_t P = pos.size();
    json findings = json::array();
    // Periodicity in cable length, pooled over the four cables
    // (identical drums share a period).
    double lo = INFINITY, hi = -INFINITY;
    for (auto &l : lmean)
        for (double v : l) {
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
    const double span = hi - lo;
    std::vector<double> freqs;
    const double fmin = 2.0 / span, fmax = 1.0 / 8.0; // periods from 8 mm to span/2
    if (fmax > fmin)
        for (int k = 0; k < 1500; ++k) freqs.push_back(fmin + (fmax - fmin) * k / 1499.0);
    std::vector<double> pooled(freqs.size(), 0);
    for (int c = 0; c < 4 && !freqs.empty(); ++c) {
        std::vector<double> t, y;
        for (size_t j = 0; j < P; ++j) {
            t.push_back(lmean[j][size_t(c)]);
            y.push_back(lres[j][size_t(c)]);
        }
        // A smooth trend in length (gain, non-linearity) would swamp the
        // low frequencies: take a quadratic out first.
        detrend_quadratic(t, y);
        auto pw = lomb(t, y, freqs);
        for (size_t f = 0; f < freqs.size(); ++f) pooled[f] += pw[f];
    }
    if (!freqs.empty()) {
        size_t bf = size_t(std::max_element(pooled.begin(), pooled.end()) - pooled.begin());
        const double z = pooled[bf];
        // Each normalised power is ~Exp(1) under noise; the sum of four ~Gamma(4,1).
        const double sf = std::exp(-z) * (1 + z + z * z / 2 + z * z * z / 6);
        const double M = span * (fmax - fmin);
        const double fap = -std::expm1(M * std::log1p(-std::min(sf, 1 - 1e-16)));
        // amplitude at that period, mean over cables
        double amp = 0;
        for (int c = 0; c < 4; ++c) {
            Eigen::MatrixXd A(P, 5);
            Eigen::VectorXd b(P);
            for (size_t j = 0; j < P; ++j) {
                const double l = lmean[j][size_t(c)], ph = 2 * M_PI * freqs[bf] * l, u = (l - lo) / span;
                A(long(j), 0) = 1;
                A(long(j), 1) = std::sin(ph);
                A(long(j), 2) = std::cos(ph);
                A(long(j), 3) = u;
                A(long(j), 4) = u * u;
                b(long(j)) = lres[j][size_t(c)];
            }
            Eigen::VectorXd s = A.colPivHouseholderQr().solve(b);
            amp += std::hypot(s(1), s(2)) / 4;
        }
        if (fap < 1e-3)
            findings.push_back({{"variable", "cable length"}, {"variable_kind", "length"}, {"cable", nullptr},
                                {"kind", "periodic"}, {"axis", "length"}, {"period_mm", 1.0 / freqs[bf]},
                                {"amplitude_mm", amp}, {"p_value", fap}, {"r2", nullptr},
                                {"text", "the cable-length residual repeats every " +
                                             std::to_string(1.0 / freqs[bf]).substr(0, 6) + " mm of cable (amplitude " +
                                             std::to_string(amp).substr(0, 6) +
                                             " mm) in all four cables: something turns with the drum (eccentric "
                                             "drum or shaft, pot track ripple)"}});
    }
    // Trends of the position residual against physical variables.
    // kind and cable travel in the finding beside the English name, so
    // that the report routes it without parsing the text.
    struct Var {
        std::string name, kind;
        json cable;
        std::vector<double> v;
    };
    std::vector<Var> vars;
    Var h{"height", "height", nullptr, {}}, rho{"distance from centre", "radius", nullptr, {}};
    for (size_t j = 0; j < P; ++j) {
        h.v.push_back(pos[j].ref(0));
        rho.v.push_back(std::hypot(pos[j].ref(1), pos[j].ref(2)));
    }
    vars.push_back(h);
    vars.push_back(rho);
    for (int c = 0; c < 4; ++c) {
        Var l{"l" + std::to_string(c + 1), "length", c + 1, {}},
            an{"angle of cable " + std::to_string(c + 1), "angle", c + 1, {}};
        for (size_t j = 0; j < P; ++j) {
            l.v.push_back(lmean[j][size_t(c)]);
            an.v.push_back(angle[j][size_t(c)]);
        }
        vars.push_back(l);
        vars.push_back(an);
    }
    std::vector<json> tr;
    for (auto &var : vars)
        for (int a = 0; a < 3; ++a) {
            std::vector<double> x, y, w;
            for (size_t j = 0; j < P; ++j)
                if (bE.ok[j]) {
                    x.push_back(var.v[j]);
                    y.push_back(bE.res[j](a));
                    w.push_back(1.0 / (bE.var_mean[j](a) + jig(a) * jig(a)));
                }
            Trend t = poly_trend(x, y, w, 2);
            if (t.p < 1e-3)
                tr.push_back({{"variable", var.name}, {"variable_kind", var.kind}, {"cable", var.cable},
                              {"kind", "trend"}, {"axis", kAxis[a]}, {"period_mm", nullptr},
                              {"amplitude_mm", t.range}, {"p_value", t.p}, {"r2", t.r2},
                              {"text", std::string(kAxis[a]) + " residual varies with " + var.name + " by " +
                                           std::to_string(t.range).substr(0, 6) + " mm (R^2 " +
                                           std::to_string(t.r2).substr(0, 4) + ")"}});
        }
    std::sort(tr.begin(), tr.end(), [](const json &a, const json &b) { return a["r2"] > b["r2"]; });
    for (size_t k = 0; k < std::min<size_t>(6, tr.size()); ++k) findings.push_back(tr[k]);
    return findings;
}

} // namespace diag
} // namespace cdm

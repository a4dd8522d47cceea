// See diagnose.h. Statistics live here; docs/calibration.md explains each.
#include "calib/diagnose.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>

#include <Eigen/Dense>

#include "calib/fit.h"
#include "cdm/cdm.h"
#include "model/effect.h"
#include "io/device_json.h"

namespace cdm {

namespace {

using nlohmann::json;
using V3 = Eigen::Vector3d;
const char *kAxis[3] = {"x", "y", "z"};

// ---------------------------------------------------------------- statistics

double normal_sf(double z) { return 0.5 * std::erfc(z / std::sqrt(2.0)); }

// Upper tail of chi-square (Wilson-Hilferty; good to a few % in the tail
// for dof > 10, which is all we use it for besides chi2_3 below).
double chi2_sf(double x, double dof) {
    if (dof <= 0) return 1.0;
    const double t = (std::cbrt(x / dof) - (1 - 2 / (9 * dof))) / std::sqrt(2 / (9 * dof));
    return normal_sf(t);
}
double chi2_3_sf(double x) { // exact, 3 dof
    return std::erfc(std::sqrt(x / 2)) + std::sqrt(2 * x / M_PI) * std::exp(-x / 2);
}
double chi2_3_isf(double p) {
    double lo = 0, hi = 1e4;
    for (int i = 0; i < 200; ++i) {
        double mid = 0.5 * (lo + hi);
        (chi2_3_sf(mid) > p ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}
// F distribution upper tail via the regularized incomplete beta (continued fraction).
double betacf(double a, double b, double x) {
    const int MAXIT = 300;
    const double EPS = 1e-14, FPMIN = 1e-300;
    double qab = a + b, qap = a + 1, qam = a - 1, c = 1, d = 1 - qab * x / qap;
    if (std::fabs(d) < FPMIN) d = FPMIN;
    d = 1 / d;
    double h = d;
    for (int m = 1; m <= MAXIT; ++m) {
        int m2 = 2 * m;
        double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1 + aa * d;
        if (std::fabs(d) < FPMIN) d = FPMIN;
        c = 1 + aa / c;
        if (std::fabs(c) < FPMIN) c = FPMIN;
        d = 1 / d;
        h *= d * c;
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1 + aa * d;
        if (std::fabs(d) < FPMIN) d = FPMIN;
        c = 1 + aa / c;
        if (std::fabs(c) < FPMIN) c = FPMIN;
        d = 1 / d;
        double del = d * c;
        h *= del;
        if (std::fabs(del - 1) < EPS) break;
    }
    return h;
}
double betai(double a, double b, double x) {
    if (x <= 0) return 0;
    if (x >= 1) return 1;
    double bt = std::exp(std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) + b * std::log(1 - x));
    if (x < (a + 1) / (a + b + 2)) return bt * betacf(a, b, x) / a;
    return 1 - bt * betacf(b, a, 1 - x) / b;
}
double f_sf(double F, double d1, double d2) {
    if (!(F > 0)) return 1.0;
    return betai(d2 / 2, d1 / 2, d2 / (d2 + d1 * F));
}

struct Acc {
    double n = 0, s = 0, ss = 0, mx = 0;
    void add(double v, double w = 1) {
        n += w;
        s += w * v;
        ss += w * v * v;
        mx = std::max(mx, std::fabs(v));
    }
    json to_json() const {
        const double mean = n > 0 ? s / n : 0;
        const double var = n > 1 ? std::max(0.0, (ss - n * mean * mean) / (n - 1)) : 0;
        return {{"mean", mean}, {"std", std::sqrt(var)}, {"rms", n > 0 ? std::sqrt(ss / n) : 0}, {"max", mx}};
    }
};
json stats3(const Acc a[3]) { return {{"x", a[0].to_json()}, {"y", a[1].to_json()}, {"z", a[2].to_json()}}; }

// ------------------------------------------------------------- evaluation

struct Eval {
    std::vector<V3> res;                           // FK(mean) - T(ref), per position
    std::vector<Eigen::Matrix<double, 3, 4>> Jp;   // d position / d readings at the estimate
    std::vector<V3> var_mean;                      // noise variance of the position mean, per axis
    std::vector<char> ok;                          // FK converged
    std::vector<V3> est;                           // estimated position (device frame)
    Acc err[3];                                    // per-sample error statistics
    Acc within[3];                                 // per-sample deviation from the position mean
    size_t bad_samples = 0;
};

Eigen::Matrix<double, 4, 3> reading_jacobian(const Model &m, const double p[3]) {
    Eigen::Matrix<double, 4, 3> J;
    for (int k = 0; k < 3; ++k) {
        double pp[3] = {p[0], p[1], p[2]}, pm[3] = {p[0], p[1], p[2]};
        pp[k] += 1e-4;
        pm[k] -= 1e-4;
        double yp[4], ym[4];
        m.readings(pp, yp);
        m.readings(pm, ym);
        for (int i = 0; i < 4; ++i) J(i, k) = (yp[i] - ym[i]) / 2e-4;
    }
    return J;
}

// Per-position residuals by FK of the mean readings; per-sample statistics
// through the local linearisation e_s = res + Jp (l_s - mean), exact to
// second order in the noise (1e-4 mm at 0.05 mm noise).
Eval evaluate(const Model &m, const Dataset &d, const std::vector<PreparedPos> &pos) {
    Eval E;
    const size_t P = pos.size();
    E.res.assign(P, V3::Zero());
    E.Jp.assign(P, Eigen::Matrix<double, 3, 4>::Zero());
    E.var_mean.assign(P, V3::Constant(1e-6));
    E.ok.assign(P, 0);
    E.est.assign(P, V3::Zero());
    for (size_t j = 0; j < P; ++j) {
        double l[4] = {pos[j].mean(0), pos[j].mean(1), pos[j].mean(2), pos[j].mean(3)};
        double p[3];
        if (m.position(l, p) != 0) {
            E.bad_samples += size_t(pos[j].n);
            continue;
        }
        double t[3];
        m.jig_to_device(pos[j].ref.data(), t);
        E.est[j] = V3(p[0], p[1], p[2]);
        E.res[j] = E.est[j] - V3(t[0], t[1], t[2]);
        auto J = reading_jacobian(m, p);
        Eigen::Matrix3d H = J.transpose() * J;
        E.Jp[j] = H.inverse() * J.transpose();
        // Covariance of the mean readings: the samples' (cross-cable terms
        // included) over n, plus on the diagonal what prepare() added for
        // quantisation and single samples.
        Eigen::Matrix4d Cl = pos[j].cov / pos[j].n;
        for (int c = 0; c < 4; ++c) Cl(c, c) = std::max(Cl(c, c), pos[j].var_mean(c));
        Eigen::Matrix3d C = E.Jp[j] * Cl * E.Jp[j].transpose();
        for (int a = 0; a < 3; ++a) E.var_mean[j](a) = std::max(C(a, a), 1e-10);
        E.ok[j] = 1;
        for (int s = 0; s < pos[j].n; ++s) {
            const auto &ls = d.samples[pos[j].first + size_t(s)];
            Eigen::Vector4d dl(ls[0] - l[0], ls[1] - l[1], ls[2] - l[2], ls[3] - l[3]);
            V3 dev = E.Jp[j] * dl;
            for (int a = 0; a < 3; ++a) {
                E.err[a].add(E.res[j](a) + dev(a));
                E.within[a].add(dev(a));
            }
        }
    }
    return E;
}

// The seed's procedure, per sample: triangulation (eq. 1-3), optionally the
// ellipsoid (eq. 4) subtracted from x.
Eval evaluate_seed(const DeviceGeometry &g, const Dataset &d, const std::vector<PreparedPos> &pos,
                   const Ellipsoid *ell) {
    Eval E;
    const size_t P = pos.size();
    E.res.assign(P, V3::Zero());
    E.ok.assign(P, 0);
    E.est.assign(P, V3::Zero());
    E.var_mean.assign(P, V3::Constant(1e-6));
    E.Jp.assign(P, Eigen::Matrix<double, 3, 4>::Zero());
    for (size_t j = 0; j < P; ++j) {
        V3 sum = V3::Zero();
        int n = 0;
        for (int s = 0; s < pos[j].n; ++s) {
            const auto &ls = d.samples[pos[j].first + size_t(s)];
            double p[3];
            if (!triangulate(g, ls.data(), p)) {
                ++E.bad_samples;
                continue;
            }
            if (ell) p[0] -= ell->xc(p[1], p[2]);
            for (int a = 0; a < 3; ++a) E.err[a].add(p[a] - pos[j].ref(a));
            sum += V3(p[0], p[1], p[2]);
            ++n;
        }
        if (n == 0) continue;
        E.est[j] = sum / n;
        E.res[j] = E.est[j] - pos[j].ref;
        E.ok[j] = 1;
    }
    return E;
}

// The seed's eq. 5: the ellipsoid fitted to the x error of an evaluation
// over its estimated y, z, each position weighted by its sample count.
Ellipsoid ellipsoid_on(const Eval &E, const std::vector<PreparedPos> &pos) {
    std::vector<double> y, z, x, w;
    for (size_t j = 0; j < pos.size(); ++j)
        if (E.ok[j]) {
            y.push_back(E.est[j](1));
            z.push_back(E.est[j](2));
            x.push_back(E.res[j](0));
            w.push_back(pos[j].n);
        }
    return fit_ellipsoid(y, z, x, w);
}

// ------------------------------------------------------------ grid helpers

struct Grid {
    std::vector<std::vector<int>> nb;                 // neighbours (same height)
    std::vector<std::array<int, 2>> ypair, zpair;     // second-difference triples: centre j, (l, r)
    std::vector<int> ycentre, zcentre;
    std::vector<int> height_index;
    double pitch = 5;
    bool layered = true; // positions on a few fixture heights (the seed's jig)
};

Grid make_grid(const std::vector<PreparedPos> &pos, const std::vector<double> &heights) {
    Grid G;
    const size_t P = pos.size();
    G.nb.resize(P);
    G.height_index.assign(P, 0);
    // The seed's jig puts every position on one of a few fixture heights.
    // Positions scattered in x (a free-hand or robot-arm reference) form one
    // layer, and their neighbours are found in 3-D.
    G.layered = heights.size() <= std::min<size_t>(50, std::max<size_t>(1, P / 4));
    if (G.layered)
        for (size_t j = 0; j < P; ++j) {
            int best = 0;
            for (size_t h = 0; h < heights.size(); ++h)
                if (std::fabs(heights[h] - pos[j].ref(0)) < std::fabs(heights[size_t(best)] - pos[j].ref(0)))
                    best = int(h);
            G.height_index[j] = best;
        }
    // pitch: the smallest positive spacing in y or z among positions
    double pitch = INFINITY;
    std::vector<double> ys;
    for (auto &p : pos) ys.push_back(p.ref(1));
    std::sort(ys.begin(), ys.end());
    for (size_t k = 1; k < ys.size(); ++k)
        if (ys[k] - ys[k - 1] > 1e-6) pitch = std::min(pitch, ys[k] - ys[k - 1]);
    if (!std::isfinite(pitch)) pitch = 5;
    G.pitch = pitch;
    std::map<std::array<long, 3>, int> key;
    auto K = [&](int hi, double y, double z) {
        return std::array<long, 3>{hi, std::lround(y / pitch), std::lround(z / pitch)};
    };
    for (size_t j = 0; j < P; ++j) key[K(G.height_index[j], pos[j].ref(1), pos[j].ref(2))] = int(j);
    auto find = [&](int hi, double y, double z) {
        auto it = key.find(K(hi, y, z));
        return it == key.end() ? -1 : it->second;
    };
    for (size_t j = 0; j < P; ++j) {
        const int h = G.height_index[j];
        const double y = pos[j].ref(1), z = pos[j].ref(2);
        int l = find(h, y - pitch, z), r = find(h, y + pitch, z), dn = find(h, y, z - pitch), up = find(h, y, z + pitch);
        for (int q : {l, r, dn, up})
            if (q >= 0) G.nb[j].push_back(q);
        if (l >= 0 && r >= 0) {
            G.ycentre.push_back(int(j));
            G.ypair.push_back({l, r});
        }
        if (dn >= 0 && up >= 0) {
            G.zcentre.push_back(int(j));
            G.zpair.push_back({dn, up});
        }
    }
    // Irregular layouts: the nearest positions of the same layer (4 in a
    // plane, 6 in 3-D), then made symmetric (Moran's I takes w_jk = w_kj).
    const size_t knn = G.layered ? 4 : 6;
    for (size_t j = 0; j < P; ++j) {
        if (!G.nb[j].empty()) continue;
        std::vector<std::pair<double, int>> dist;
        for (size_t k = 0; k < P; ++k)
            if (k != j && G.height_index[k] == G.height_index[j])
                dist.push_back({(pos[k].ref - pos[j].ref).squaredNorm(), int(k)});
        std::sort(dist.begin(), dist.end());
        for (size_t k = 0; k < std::min(knn, dist.size()); ++k) G.nb[j].push_back(dist[k].second);
    }
    std::vector<std::vector<int>> sym(P);
    for (size_t j = 0; j < P; ++j)
        for (int k : G.nb[j]) {
            sym[j].push_back(k);
            sym[size_t(k)].push_back(int(j));
        }
    for (auto &v : sym) {
        std::sort(v.begin(), v.end());
        v.erase(std::unique(v.begin(), v.end()), v.end());
    }
    G.nb = std::move(sym);
    return G;
}

// White (position-to-position) scatter beyond the noise, per axis, from
// second differences along the plate's rows and columns: a smooth error
// (an effect) nearly cancels in them, the jig's hole errors do not.
// E[(r_j - (r_l + r_r)/2)^2] = v_j + (v_l + v_r)/4 + 1.5 s^2.
V3 estimate_nugget(const Eval &E, const Grid &G) {
    V3 out;
    for (int a = 0; a < 3; ++a) {
        double num = 0, noise = 0;
        int cnt = 0;
        auto add = [&](const std::vector<int> &cen, const std::vector<std::array<int, 2>> &pr) {
            for (size_t k = 0; k < cen.size(); ++k) {
                int j = cen[k], l = pr[k][0], r = pr[k][1];
                if (!E.ok[j] || !E.ok[l] || !E.ok[r]) continue;
                double dd = E.res[j](a) - 0.5 * (E.res[l](a) + E.res[r](a));
                num += dd * dd;
                noise += E.var_mean[j](a) + 0.25 * (E.var_mean[l](a) + E.var_mean[r](a));
                ++cnt;
            }
        };
        add(G.ycentre, G.ypair);
        add(G.zcentre, G.zpair);
        if (cnt >= 20) {
            out(a) = std::sqrt(std::max(0.0, (num - noise) / (1.5 * cnt)));
            continue;
        }
        // No plate rows (an irregular layout): first differences between
        // nearest neighbours, E[(r_j - r_k)^2] = v_j + v_k + 2 s^2, which a
        // smooth error biases more (its gradient times the spacing).
        num = noise = 0;
        cnt = 0;
        for (size_t j = 0; j < G.nb.size(); ++j)
            for (int k : G.nb[j]) {
                if (size_t(k) <= j || !E.ok[j] || !E.ok[size_t(k)]) continue;
                const double dd = E.res[j](a) - E.res[size_t(k)](a);
                num += dd * dd;
                noise += E.var_mean[j](a) + E.var_mean[size_t(k)](a);
                ++cnt;
            }
        out(a) = cnt > 0 ? std::sqrt(std::max(0.0, (num - noise) / (2.0 * cnt))) : 0.0;
    }
    return out;
}

struct Verdict {
    double chi2 = 0, chi2_p = 1;
    int dof = 1;
    double moran_z = 0, moran_p = 1;
    bool explained = false;
    std::vector<char> failing;
    int n_failing = 0;
};

// Moran's I of the standardised residuals over the plate's neighbour graph,
// per axis, with each height's mean removed (a per-height offset is the
// height fixture's, and the chi-square sees it). Positive I = neighbours
// alike = smooth structure that noise does not make.
double moran_z(const std::vector<double> &zv, const std::vector<char> &ok, const Grid &G) {
    const size_t P = zv.size();
    std::map<int, std::pair<double, int>> hm;
    for (size_t j = 0; j < P; ++j)
        if (ok[j]) {
            hm[G.height_index[j]].first += zv[j];
            hm[G.height_index[j]].second += 1;
        }
    std::vector<double> c(P, 0);
    double n = 0, m2 = 0;
    for (size_t j = 0; j < P; ++j)
        if (ok[j]) {
            auto &h = hm[G.height_index[j]];
            c[j] = zv[j] - h.first / h.second;
            m2 += c[j] * c[j];
            n += 1;
        }
    double S0 = 0, S1 = 0, S2 = 0, num = 0;
    for (size_t j = 0; j < P; ++j) {
        if (!ok[j]) continue;
        double rowsum = 0;
        for (int k : G.nb[j]) {
            if (!ok[size_t(k)]) continue;
            // symmetric weights: 1 for each direction listed
            num += c[j] * c[size_t(k)];
            S0 += 1;
            S1 += 2; // (w_jk + w_kj)^2 / 2 summed over ordered pairs with symmetric w = 1
            rowsum += 1;
        }
        S2 += 4 * rowsum * rowsum;
    }
    if (S0 == 0 || m2 == 0 || n < 5) return 0;
    const double I = (n / S0) * num / m2;
    const double EI = -1.0 / (n - 1);
    const double VI = (n * n * S1 / 2 - n * S2 / 4 + 3 * S0 * S0) / ((n * n - 1) * S0 * S0) - EI * EI;
    return VI > 0 ? (I - EI) / std::sqrt(VI) : 0;
}

Verdict judge(const Eval &E, const Grid &G, const V3 &jig, int n_free) {
    Verdict v;
    const size_t P = E.res.size();
    v.failing.assign(P, 0);
    size_t used = 0;
    std::vector<double> z[3];
    for (auto &zz : z) zz.assign(P, 0);
    for (size_t j = 0; j < P; ++j)
        if (E.ok[j]) ++used;
    const double q = chi2_3_isf(0.01 / std::max<size_t>(1, used)); // 1 % family-wise
    // The height fixture's own error: one constant per height (the same at
    // every hole), like the holes' error a property of the jig, not of the
    // model. Per-height mean residuals up to 0.15 mm (3x a machined 0.05 mm
    // tolerance) are taken as the fixture's and removed before the
    // chi-square, at the cost of their degrees of freedom; larger ones stay.
    std::map<std::pair<int, int>, std::pair<double, double>> hmean; // (height, axis) -> (sum w r, sum w)
    for (size_t j = 0; j < P; ++j)
        if (E.ok[j])
            for (int a = 0; a < 3; ++a) {
                const double w = 1.0 / (E.var_mean[j](a) + jig(a) * jig(a));
                auto &h = hmean[{G.height_index[j], a}];
                h.first += w * E.res[j](a);
                h.second += w;
            }
    int nuisance = 0;
    std::map<std::pair<int, int>, double> fixture;
    for (auto &kv : hmean) {
        const double m = kv.second.first / kv.second.second;
        if (std::fabs(m) <= 0.15) {
            fixture[kv.first] = m;
            ++nuisance;
        }
    }
    for (size_t j = 0; j < P; ++j) {
        if (!E.ok[j]) continue;
        double c = 0;
        for (int a = 0; a < 3; ++a) {
            const double s2 = E.var_mean[j](a) + jig(a) * jig(a);
            auto it = fixture.find({G.height_index[j], a});
            const double off = it == fixture.end() ? 0.0 : it->second;
            z[a][j] = (E.res[j](a) - off) / std::sqrt(s2);
            c += z[a][j] * z[a][j];
        }
        v.chi2 += c;
        if (c > q) {
            v.failing[j] = 1;
            ++v.n_failing;
        }
    }
    v.dof = std::max(1, int(3 * used) - n_free - nuisance);
    v.chi2_p = chi2_sf(v.chi2, v.dof);
    double best = -INFINITY;
    for (int a = 0; a < 3; ++a) best = std::max(best, moran_z(z[a], E.ok, G));
    v.moran_z = best;
    v.moran_p = std::min(1.0, 3 * normal_sf(best)); // Bonferroni over the three axes
    v.explained = v.chi2_p >= 1e-3 && v.moran_p >= 1e-3;
    return v;
}

json vec3(const V3 &v) { return json::array({v(0), v(1), v(2)}); }

// Lomb-Scargle periodogram of y(t) (mean removed), normalised by the variance.
std::vector<double> lomb(const std::vector<double> &t, const std::vector<double> &y, const std::vector<double> &freqs) {
    const size_t n = t.size();
    double mean = 0, var = 0;
    for (double v : y) mean += v;
    mean /= double(n);
    for (double v : y) var += (v - mean) * (v - mean);
    var /= double(n - 1);
    std::vector<double> P(freqs.size(), 0);
    for (size_t f = 0; f < freqs.size(); ++f) {
        const double w = 2 * M_PI * freqs[f];
        double s2 = 0, c2 = 0;
        for (size_t k = 0; k < n; ++k) {
            s2 += std::sin(2 * w * t[k]);
            c2 += std::cos(2 * w * t[k]);
        }
        const double tau = std::atan2(s2, c2) / (2 * w);
        double yc = 0, ys = 0, cc = 0, ss = 0;
        for (size_t k = 0; k < n; ++k) {
            const double c = std::cos(w * (t[k] - tau)), s = std::sin(w * (t[k] - tau));
            yc += (y[k] - mean) * c;
            ys += (y[k] - mean) * s;
            cc += c * c;
            ss += s * s;
        }
        P[f] = var > 0 ? 0.5 * (yc * yc / cc + ys * ys / ss) / var : 0;
    }
    return P;
}

void detrend_quadratic(const std::vector<double> &t, std::vector<double> &y) {
    const size_t n = t.size();
    if (n < 4) return;
    double lo = *std::min_element(t.begin(), t.end()), hi = *std::max_element(t.begin(), t.end());
    const double span = hi > lo ? hi - lo : 1.0;
    Eigen::MatrixXd A(n, 3);
    Eigen::VectorXd b(n);
    for (size_t k = 0; k < n; ++k) {
        const double u = (t[k] - lo) / span;
        A(long(k), 0) = 1;
        A(long(k), 1) = u;
        A(long(k), 2) = u * u;
        b(long(k)) = y[k];
    }
    Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
    Eigen::VectorXd r = b - A * c;
    for (size_t k = 0; k < n; ++k) y[k] = r(long(k));
}

// Least-squares polynomial fit of degree deg; returns the F-test p-value
// against a constant and the fitted curve's range.
struct Trend {
    double p = 1, range = 0, r2 = 0;
};
Trend poly_trend(const std::vector<double> &x, const std::vector<double> &y, const std::vector<double> &w, int deg) {
    const size_t n = x.size();
    Trend t;
    if (n < size_t(deg + 3)) return t;
    double xm = 0, sw = 0;
    for (size_t k = 0; k < n; ++k) {
        xm += w[k] * x[k];
        sw += w[k];
    }
    xm /= sw;
    double xs = 0;
    for (size_t k = 0; k < n; ++k) xs = std::max(xs, std::fabs(x[k] - xm));
    if (xs == 0) return t;
    Eigen::MatrixXd A(n, deg + 1);
    Eigen::VectorXd b(n), sq(n);
    for (size_t k = 0; k < n; ++k) {
        const double u = (x[k] - xm) / xs, s = std::sqrt(w[k]);
        for (int d = 0; d <= deg; ++d) A(long(k), d) = s * std::pow(u, d);
        b(long(k)) = s * y[k];
    }
    Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
    const double rss = (A * c - b).squaredNorm();
    double mean = 0;
    for (size_t k = 0; k < n; ++k) mean += w[k] * y[k];
    mean /= sw;
    double tss = 0;
    for (size_t k = 0; k < n; ++k) tss += w[k] * (y[k] - mean) * (y[k] - mean);
    if (tss <= 0) return t;
    const double F = ((tss - rss) / deg) / (rss / double(n - size_t(deg) - 1));
    t.p = f_sf(F, deg, double(n) - deg - 1);
    t.r2 = 1 - rss / tss;
    double lo = INFINITY, hi = -INFINITY;
    for (size_t k = 0; k < n; ++k) {
        double u = (x[k] - xm) / xs, v = 0;
        for (int d = 0; d <= deg; ++d) v += c(d) * std::pow(u, d);
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    t.range = hi - lo;
    return t;
}

} // namespace

// ============================================================== diagnose

bool diagnose(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out, Model &fitted,
              std::string &err) {
    auto t0 = std::chrono::steady_clock::now();
    auto progress = [&](const std::string &s, double f) { return !opt.progress || opt.progress(s, f); };
    const auto pos = prepare(data);
    const size_t P = pos.size();
    if (P < 4) {
        err = data.path + ": " + std::to_string(P) + " jig positions; a diagnosis needs at least 4";
        return false;
    }
    const Grid G = make_grid(pos, data.heights);
    // A machined plate is within ~0.05 mm: white scatter beyond that is not
    // the jig's and must not hide an effect. Without repeated samples the
    // pots' noise is white scatter too, and there is nothing to cap against.
    const bool repeats = std::any_of(pos.begin(), pos.end(), [](const PreparedPos &p) { return p.n > 1; });
    const double jig_cap = repeats ? 0.05 : INFINITY;

    // --- the seed's procedure: nominal triangulation, then the ellipsoid
    progress("nominal model", 0.0);
    Eval nom = evaluate_seed(g, data, pos, nullptr);
    Ellipsoid ell = ellipsoid_on(nom, pos);
    Eval ellE = evaluate_seed(g, data, pos, &ell);

    // --- the model
    Model model(g);
    for (auto &e : opt.effects) {
        if (e == "ellipsoid") continue; // fitted in position space below
        if (!model.add_effect(e, {}, err)) return false;
    }
    const bool user_jig = opt.jig_tolerance_mm >= 0;
    V3 jig = V3::Constant(user_jig ? opt.jig_tolerance_mm : 0.03);
    FitOptions fo;
    fo.jig_sigma = jig;
    FitReport rep;
    auto fit_with_progress = [&](Model &m, FitOptions f, const std::string &stage, FitReport &r) {
        f.progress = [&](double fr) { return progress(stage, fr); };
        return fit_model(m, pos, f, r);
    };
    if (!fit_with_progress(model, fo, "fitting the model", rep)) {
        err = rep.message.empty() ? "fit cancelled" : rep.message;
        return false;
    }
    Eval cur = evaluate(model, data, pos);
    // Jig tolerance from the white part of the residual, then refit with it.
    if (!user_jig) {
        V3 est = estimate_nugget(cur, G);
        for (int a = 0; a < 3; ++a) jig(a) = std::min(est(a), jig_cap);
        fo.jig_sigma = jig;
        if (model.effect_count() > 0) {
            fit_with_progress(model, fo, "fitting the model", rep);
            cur = evaluate(model, data, pos);
        }
    }
    // The ellipsoid on top of the physical model, when asked for.
    bool model_has_ellipsoid = std::find(opt.effects.begin(), opt.effects.end(), "ellipsoid") != opt.effects.end();
    if (model_has_ellipsoid) {
        Ellipsoid e2 = ellipsoid_on(cur, pos);
        std::string e3;
        model.add_effect("ellipsoid", {{"L", e2.L}, {"M", e2.M}, {"N", e2.N}}, e3);
        cur = evaluate(model, data, pos);
        rep.n_free += 3;
    }
    Verdict vcur = judge(cur, G, jig, rep.n_free);
    const double n_obs = 4.0 * double(P);
    // The fitted model's reading-space chi-square, the reference every
    // candidate and every review refit is compared with.
    const double chi2_cur = model_chi2(model, pos, fo);

    // --- candidates
    struct Cand {
        std::string name;
        double dchi2 = 0, bic = 0, score = 0, corr = 0;
        int k = 0;
        Eval E;
        Verdict v;
        Model m;
        std::vector<V3> fp;
        std::vector<std::string> in_model; // model effects that reproduce it
    };
    std::vector<Cand> cands;
    if (opt.candidates) {
        auto list = candidate_effects();
        size_t done = 0;
        for (auto &d : list) {
            ++done;
            if (model.has_effect(d->name)) continue;
            Cand c{d->name, 0, 0, 0, 0, 0, {}, {}, model, {}, {}};
            std::string e2;
            if (!c.m.add_effect(d->name, {}, e2)) continue;
            FitReport r2;
            if (!fit_with_progress(c.m, fo, "scoring " + d->name, r2)) {
                err = r2.message.empty() ? "fit cancelled" : r2.message;
                return false;
            }
            c.k = r2.n_free - (rep.n_free - (model_has_ellipsoid ? 3 : 0));
            // What the model already does that this effect would: an effect
            // the model's own effects reproduce cannot be told from them.
            if (model.effect_count() > (model_has_ellipsoid ? 1u : 0u)) {
                Overlap ov = effect_overlap(c.m, pos, fo, d->name);
                for (auto &pe : ov.per_effect)
                    if (pe.second > 0.99) c.in_model.push_back(pe.first);
                if (c.in_model.empty() && ov.all > 0.99)
                    for (auto &pe : ov.per_effect) c.in_model.push_back(pe.first);
            }
            if (c.k <= 0) continue; // nothing left to fit after the gauge: indistinguishable from the model
            c.dchi2 = chi2_cur - r2.chi2;
            c.bic = -c.dchi2 + c.k * std::log(n_obs);
            c.score = -c.bic;
            c.E = evaluate(c.m, data, pos);
            // Each explanation is judged with the white scatter its own
            // residual shows: a large smooth residual biases the nugget.
            V3 jc = jig;
            if (!user_jig) {
                V3 est = estimate_nugget(c.E, G);
                for (int a = 0; a < 3; ++a) jc(a) = std::min(est(a), jig_cap);
            }
            c.v = judge(c.E, G, jc, r2.n_free);
            c.fp.resize(P);
            double sxy = 0, sxx = 0, syy = 0;
            for (size_t j = 0; j < P; ++j) {
                c.fp[j] = cur.res[j] - c.E.res[j];
                for (int a = 0; a < 3; ++a) {
                    const double s2 = cur.var_mean[j](a) + jig(a) * jig(a);
                    sxy += c.fp[j](a) * cur.res[j](a) / s2;
                    sxx += c.fp[j](a) * c.fp[j](a) / s2;
                    syy += cur.res[j](a) * cur.res[j](a) / s2;
                }
            }
            c.corr = (sxx > 0 && syy > 0) ? sxy / std::sqrt(sxx * syy) : 0;
            cands.push_back(std::move(c));
            progress("candidates", double(done) / double(list.size()));
        }
        std::sort(cands.begin(), cands.end(), [](const Cand &a, const Cand &b) { return a.bic < b.bic; });
    }
    // Confusion: two candidates that explain the same residual about as well.
    auto fp_corr = [&](const Cand &a, const Cand &b) {
        double sab = 0, saa = 0, sbb = 0;
        for (size_t j = 0; j < P; ++j)
            for (int k = 0; k < 3; ++k) {
                const double s2 = cur.var_mean[j](k) + jig(k) * jig(k);
                sab += a.fp[j](k) * b.fp[j](k) / s2;
                saa += a.fp[j](k) * a.fp[j](k) / s2;
                sbb += b.fp[j](k) * b.fp[j](k) / s2;
            }
        return (saa > 0 && sbb > 0) ? sab / std::sqrt(saa * sbb) : 0.0;
    };
    std::vector<std::vector<std::string>> confused(cands.size());
    for (size_t a = 0; a < cands.size(); ++a) confused[a] = cands[a].in_model;
    for (size_t a = 0; a < cands.size(); ++a)
        for (size_t b = 0; b < cands.size(); ++b) {
            if (a == b || cands[a].bic >= 0 || cands[b].bic >= 0) continue;
            // Equally good (BIC within 10: "very strong" evidence on
            // Kass-Raftery's scale is needed to prefer one) and explaining
            // the same pattern.
            if (std::fabs(cands[a].bic - cands[b].bic) < 10 && fp_corr(cands[a], cands[b]) > 0.9)
                confused[a].push_back(cands[b].name);
        }

    // --- model review: is each effect in the model still earning its
    // parameters, and would a candidate do its job better? Greedy forward
    // selection can pick a many-parameter effect that mimics two small ones
    // (anchors for a jig tilt plus a gain error); this catches it.
    json review = json::array();
    {
        const double bic_cur = chi2_cur + rep.n_free * std::log(n_obs);
        auto rebuild = [&](const std::string &skip, const std::string &add, Model &m2) {
            std::string e2;
            for (size_t q = 0; q < model.effect_count(); ++q) {
                const EffectDesc &d = model.effect_desc(q);
                if (d.name == skip || d.stage == Stage::Position) continue;
                ParamValues pv;
                for (size_t k = 0; k < d.params.size(); ++k) pv.emplace_back(d.params[k].name, model.effect_params(q)[k]);
                m2.add_effect(d.name, pv, e2);
            }
            if (!add.empty()) m2.add_effect(add, {}, e2);
        };
        for (size_t q = 0; q < model.effect_count(); ++q) {
            if (model.effect_desc(q).stage == Stage::Position) continue;
            const std::string name = model.effect_name(q);
            Model without{g};
            rebuild(name, "", without);
            FitReport rw;
            fit_with_progress(without, fo, "reviewing " + name, rw);
            const double bic_without = rw.chi2 + rw.n_free * std::log(n_obs);
            json item = {{"effect", name}, {"bic_change_if_removed", bic_without - bic_cur},
                         {"redundant", bic_without - bic_cur < 10}};
            double best = 0;
            std::string best_name;
            // Every catalogued effect not in the model (not only the ranked
            // candidates: one that adds no free parameter to the model, like
            // the jig transform beside the anchors, can still replace one).
            for (auto &cd : candidate_effects()) {
                if (model.has_effect(cd->name)) continue;
                Model swapped{g};
                rebuild(name, cd->name, swapped);
                FitReport rs;
                fit_with_progress(swapped, fo, "reviewing " + name, rs);
                const double d = rs.chi2 + rs.n_free * std::log(n_obs) - bic_cur;
                if (d < best) {
                    best = d;
                    best_name = cd->name;
                }
            }
            if (best < -10) item["better_swap"] = {{"effect", best_name}, {"bic_change", best}};
            review.push_back(item);
        }
    }

    // --- leave-one-height-out validation
    json validation = nullptr;
    if (opt.validation && rep.n_free > 0 && G.layered && data.heights.size() > 1 && data.heights.size() <= 20) {
        Acc held[3];
        json folds = json::array();
        for (size_t h = 0; h < data.heights.size(); ++h) {
            Model mv = model;
            FitOptions fv = fo;
            fv.use.assign(P, 0);
            for (size_t j = 0; j < P; ++j) fv.use[j] = G.height_index[j] != int(h);
            FitReport rv;
            if (!fit_with_progress(mv, fv, "validation", rv)) {
                err = rv.message.empty() ? "fit cancelled" : rv.message;
                return false;
            }
            Eval ev = evaluate(mv, data, pos);
            Acc f[3];
            for (size_t j = 0; j < P; ++j)
                if (!fv.use[j] && ev.ok[j])
                    for (int a = 0; a < 3; ++a) {
                        f[a].add(ev.res[j](a));
                        held[a].add(ev.res[j](a));
                    }
            folds.push_back({{"height", data.heights[h]},
                             {"rms_mm", {{"x", f[0].to_json()["rms"]}, {"y", f[1].to_json()["rms"]}, {"z", f[2].to_json()["rms"]}}}});
        }
        Acc ins[3];
        for (size_t j = 0; j < P; ++j)
            if (cur.ok[j])
                for (int a = 0; a < 3; ++a) ins[a].add(cur.res[j](a));
        validation = {{"method", "leave-one-height-out"},
                      {"folds", folds},
                      {"rms_mm", {{"x", held[0].to_json()["rms"]}, {"y", held[1].to_json()["rms"]}, {"z", held[2].to_json()["rms"]}}},
                      {"in_sample_rms_mm", {{"x", ins[0].to_json()["rms"]}, {"y", ins[1].to_json()["rms"]}, {"z", ins[2].to_json()["rms"]}}}};
    }

    // --- beyond the catalogue: what is left after the best catalogued
    // explanation (the current model, or the top candidate on top of it when
    // neither explains the data), against physical variables
    progress("residual analysis", 0.0);
    const bool use_top = !vcur.explained && !cands.empty() && cands[0].bic < 0 && !cands[0].v.explained;
    const Model &basis = use_top ? cands[0].m : model;
    const Eval &bE = use_top ? cands[0].E : cur;
    std::vector<std::array<double, 4>> lres(P), lmean(P), angle(P);
    for (size_t j = 0; j < P; ++j) {
        double t[3], y[4];
        basis.jig_to_device(pos[j].ref.data(), t);
        basis.readings(t, y);
        const auto A = g;
        for (int c = 0; c < 4; ++c) {
            lres[j][size_t(c)] = pos[j].mean(c) - y[c];
            lmean[j][size_t(c)] = pos[j].mean(c);
            auto an = A.anchor(c);
            auto ho = A.holder(c);
            double d[3] = {t[0] + ho[0] - an[0], t[1] + ho[1] - an[1], t[2] + ho[2] - an[2]};
            angle[j][size_t(c)] = std::atan2(d[0], std::hypot(d[1], d[2])) * 180 / M_PI;
        }
    }
    json findings = json::array();
    {
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
                findings.push_back({{"variable", "cable length"}, {"kind", "periodic"}, {"axis", "length"},
                                    {"period_mm", 1.0 / freqs[bf]}, {"amplitude_mm", amp}, {"p_value", fap},
                                    {"text", "the cable-length residual repeats every " +
                                                 std::to_string(1.0 / freqs[bf]).substr(0, 6) + " mm of cable (amplitude " +
                                                 std::to_string(amp).substr(0, 6) +
                                                 " mm) in all four cables: something turns with the drum (eccentric "
                                                 "drum or shaft, pot track ripple)"}});
        }
        // Trends of the position residual against physical variables.
        struct Var {
            std::string name;
            std::vector<double> v;
        };
        std::vector<Var> vars;
        Var h{"height", {}}, rho{"distance from centre", {}};
        for (size_t j = 0; j < P; ++j) {
            h.v.push_back(pos[j].ref(0));
            rho.v.push_back(std::hypot(pos[j].ref(1), pos[j].ref(2)));
        }
        vars.push_back(h);
        vars.push_back(rho);
        for (int c = 0; c < 4; ++c) {
            Var l{"l" + std::to_string(c + 1), {}}, an{"angle of cable " + std::to_string(c + 1), {}};
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
                    tr.push_back({{"variable", var.name}, {"kind", "trend"}, {"axis", kAxis[a]}, {"period_mm", nullptr},
                                  {"amplitude_mm", t.range}, {"p_value", t.p}, {"r2", t.r2},
                                  {"text", std::string(kAxis[a]) + " residual varies with " + var.name + " by " +
                                               std::to_string(t.range).substr(0, 6) + " mm (R^2 " +
                                               std::to_string(t.r2).substr(0, 4) + ")"}});
            }
        std::sort(tr.begin(), tr.end(), [](const json &a, const json &b) { return a["r2"] > b["r2"]; });
        for (size_t k = 0; k < std::min<size_t>(6, tr.size()); ++k) findings.push_back(tr[k]);
    }

    // --- verdict
    const Cand *top = cands.empty() ? nullptr : &cands[0];
    std::string verdict, unexplained_summary;
    auto errx = [](const Eval &E) { return E.err[0].to_json()["rms"].get<double>(); };
    auto fmt = [](double v, int prec = 3) {
        char b[64];
        std::snprintf(b, sizeof b, "%.*f", prec, v);
        return std::string(b);
    };
    std::string modelname = "the nominal model";
    if (model.effect_count()) {
        modelname = "the model with ";
        for (size_t k = 0; k < model.effect_count(); ++k) modelname += (k ? ", " : "") + model.effect_name(k);
    }
    if (vcur.explained) {
        verdict = modelname + " explains the data: the residual is consistent with the pots' repeatability and the jig's "
                  "tolerance (chi2/dof " + fmt(vcur.chi2 / vcur.dof, 2) + ", spatial structure p = " + fmt(vcur.moran_p, 3) +
                  ").";
        unexplained_summary = "nothing left to explain";
    } else if (top && top->bic < 0 && top->v.explained) {
        verdict = modelname + " leaves structured error (x RMS " + fmt(errx(cur)) + " mm, structure z = " +
                  fmt(vcur.moran_z, 1) + "). Missing effect: " + top->name + " (delta chi2 " + fmt(top->dchi2, 0) +
                  "); with it the x RMS falls to " + fmt(errx(top->E)) + " mm and the residual is consistent with noise.";
        if (!confused[0].empty()) {
            verdict += " The data cannot tell it from: ";
            for (size_t k = 0; k < confused[0].size(); ++k) verdict += (k ? ", " : "") + confused[0][k];
            verdict += " (see inseparable).";
        }
        verdict += " Add it with --effects.";
        unexplained_summary = "explained by a catalogued effect (" + top->name + ")";
    } else if (top && top->bic < 0 && vcur.chi2 - top->v.chi2 >= 0.5 * (vcur.chi2 - vcur.dof)) {
        verdict = modelname + " leaves structured error; the best catalogued effect, " + top->name +
                  ", explains part of it (x RMS " + fmt(errx(cur)) + " -> " + fmt(errx(top->E)) +
                  " mm) but structure remains after it (z = " + fmt(top->v.moran_z, 1) +
                  "). Either several effects are missing (add " + top->name +
                  " and diagnose again) or an effect outside the catalogue is at work: see unexplained_structure.";
        unexplained_summary = "not fully explained by any single catalogued effect";
    } else {
        verdict = modelname + " leaves structured error (x RMS " + fmt(errx(cur)) + " mm, structure z = " +
                  fmt(vcur.moran_z, 1) + ") and no effect in the catalogue explains it";
        if (top && top->bic < 0)
            verdict += " (the best, " + top->name + ", removes only " +
                       fmt(std::max(0.0, 100 * (vcur.chi2 - top->v.chi2) / std::max(1.0, vcur.chi2 - vcur.dof)), 0) +
                       " % of the excess chi-square)";
        verdict += ". See unexplained_structure for the residual against the physical variables; a user-defined "
                   "effect (docs/calibration.md) can then be fitted like a catalogued one.";
        unexplained_summary = "no catalogued effect explains the residual";
    }
    for (auto &r : review) {
        if (r.contains("better_swap"))
            verdict += " Review: replacing " + r["effect"].get<std::string>() + " with " +
                       r["better_swap"]["effect"].get<std::string>() + " explains the data as well with fewer "
                       "parameters (BIC " + fmt(r["better_swap"]["bic_change"].get<double>(), 0) + ").";
        else if (r["redundant"].get<bool>())
            verdict += " Review: " + r["effect"].get<std::string>() +
                       " no longer earns its parameters (removing it changes BIC by " +
                       fmt(r["bic_change_if_removed"].get<double>(), 0) + ").";
    }
    if (!vcur.explained && !(top && top->v.explained) && !findings.empty()) {
        unexplained_summary += "; found: ";
        for (size_t k = 0; k < std::min<size_t>(3, findings.size()); ++k)
            unexplained_summary += (k ? "; " : "") + findings[k]["text"].get<std::string>();
    }

    // --- JSON
    out = json::object();
    out["tool"] = "cdm calib diagnose";
    // The header's version, not cdm_version(): calib sits below the API layer.
    out["version"] = std::to_string(CDM_VERSION_MAJOR) + "." + std::to_string(CDM_VERSION_MINOR) + "." + std::to_string(CDM_VERSION_PATCH);
    out["data"] = {{"path", data.path},
                   {"rows", data.rows},
                   {"positions", P},
                   {"heights", data.heights},
                   {"ignored_columns", data.ignored_columns},
                   {"out_of_workspace_samples", nom.bad_samples}};
    out["device"] = io::device_to_json(g);
    json mlist = json::array(), params = json::object();
    for (size_t k = 0; k < model.effect_count(); ++k) {
        mlist.push_back(model.effect_name(k));
        const EffectDesc &desc = model.effect_desc(k);
        const auto &val = model.effect_params(k);
        json pj = json::object();
        for (size_t q = 0; q < val.size(); ++q) {
            double sd = (k < rep.std.size() && q < rep.std[k].size()) ? rep.std[k][q] : 0.0;
            pj[desc.params[q].name] = {{"value", val[q]}, {"std", sd}, {"unit", desc.params[q].unit}};
        }
        params[model.effect_name(k)] = pj;
    }
    out["model"] = mlist;
    out["params"] = params;
    out["fit"] = {{"algorithm", rep.algorithm}, {"evaluations", rep.evals}, {"seconds", rep.seconds},
                  {"converged", rep.converged}, {"free_parameters", rep.n_free}, {"message", rep.message}};
    out["error_mm"] = stats3(cur.err);
    out["nominal_error_mm"] = stats3(nom.err);
    out["ellipsoid_error_mm"] = stats3(ellE.err);
    out["ellipsoid"] = {{"L", ell.L}, {"M", ell.M}, {"N", ell.N}};
    {
        json nf;
        for (int a = 0; a < 3; ++a) {
            const double w = cur.within[a].n > 1 ? cur.within[a].ss / cur.within[a].n : 0;
            const double s = std::sqrt(w + jig(a) * jig(a));
            nf[kAxis[a]] = {{"mean", 0.0}, {"std", s}, {"rms", s}, {"max", cur.within[a].mx}};
        }
        out["noise_floor_mm"] = nf;
    }
    out["jig_tolerance_mm"] = {{"value", std::sqrt(0.5 * (jig(1) * jig(1) + jig(2) * jig(2)))},
                               {"per_axis", vec3(jig)},
                               {"source", user_jig ? "user" : "estimated"},
                               {"note", repeats ? "white position-to-position scatter beyond the pots' repeatability, "
                                                  "from second differences along the plate; capped at 0.05 mm"
                                                : "no repeated samples: the pots' noise and the jig's scatter cannot be "
                                                  "told apart, both are in this estimate"}};
    out["chi2_per_dof"] = vcur.chi2 / vcur.dof;
    out["dof"] = vcur.dof;
    out["chi2_p_value"] = vcur.chi2_p;
    out["structure"] = {{"statistic", vcur.moran_z},
                        {"p_value", vcur.moran_p},
                        {"method", "Moran's I of the standardised position residuals over the plate's neighbour "
                                   "graph, per axis, per-height means removed; z-score, max over axes, Bonferroni p"}};
    out["explained"] = vcur.explained;
    out["verdict"] = verdict;
    out["failing_positions"] = vcur.n_failing;
    json cj = json::array();
    for (size_t a = 0; a < cands.size(); ++a) {
        auto &c = cands[a];
        cj.push_back({{"effect", c.name},
                      {"score", c.score},
                      {"delta_chi2", c.dchi2},
                      {"bic_change", c.bic},
                      {"n_params", c.k},
                      {"error_mm_after", stats3(c.E.err)},
                      {"explained_after", c.v.explained},
                      {"chi2_per_dof_after", c.v.chi2 / c.v.dof},
                      {"structure_after", c.v.moran_z},
                      {"confused_with", confused[a]},
                      {"residual_correlation", c.corr}});
    }
    out["candidates"] = cj;
    // Inseparable groups, with where their predictions part.
    json insep = json::array();
    std::vector<char> seen(cands.size(), 0);
    for (size_t a = 0; a < cands.size(); ++a) {
        if (seen[a] || confused[a].empty()) continue;
        json grp = json::array({cands[a].name});
        seen[a] = 1;
        std::string sep;
        for (auto &nm : confused[a]) {
            grp.push_back(nm);
            for (size_t b = 0; b < cands.size(); ++b)
                if (cands[b].name == nm) {
                    seen[b] = 1;
                    // probe heights and radii beyond the measured ones
                    double best = -1, bh = 0, by = 0, bz = 0;
                    for (double hx = 10; hx <= 110; hx += 10)
                        for (double yy = -90; yy <= 90; yy += 15)
                            for (double zz = -90; zz <= 90; zz += 15) {
                                double pa[3] = {hx, yy, zz}, ra[4], rb[4], ta[3], tb[3];
                                cands[a].m.jig_to_device(pa, ta);
                                cands[b].m.jig_to_device(pa, tb);
                                cands[a].m.readings(ta, ra);
                                cands[b].m.readings(tb, rb);
                                double dmax = 0;
                                for (int c = 0; c < 4; ++c) dmax = std::max(dmax, std::fabs(ra[c] - rb[c]));
                                if (dmax > best) {
                                    best = dmax;
                                    bh = hx;
                                    by = yy;
                                    bz = zz;
                                }
                            }
                    sep += (sep.empty() ? "" : "; ") + cands[a].name + " vs " + nm;
                    // 0.01 mm: a position mean of 100 samples at 0.05 mm noise.
                    if (best < 0.01)
                        sep += ": they predict the same readings everywhere (at most " + fmt(best, 4) +
                               " mm apart out to x = 10..110, y, z = +-90 mm): no jig measurement separates them; "
                               "they are one effect as far as the cable lengths can tell, keep either";
                    else
                        sep += ": their readings differ most (" + fmt(best) + " mm) at x = " + fmt(bh, 0) + ", y = " +
                               fmt(by, 0) + ", z = " + fmt(bz, 0) +
                               " mm; measure positions toward there (other heights, further out) to separate them";
                }
            bool is_cand = false;
            for (auto &c : cands) is_cand = is_cand || c.name == nm;
            if (!is_cand)
                sep += (sep.empty() ? "" : "; ") + nm + " (already in the model) reproduces what " + cands[a].name +
                       " would do: adding it changes nothing the data can see";
        }
        insep.push_back({{"effects", grp}, {"separate_by", sep}});
    }
    out["inseparable"] = insep;
    out["model_review"] = review;
    out["unexplained_structure"] = {{"summary", unexplained_summary},
                                    {"residual_of", use_top ? "the model plus " + cands[0].name : modelname},
                                    {"findings", findings}};
    out["validation"] = validation;
    if (opt.per_position) {
        json pj;
        json point = json::array(), ref = json::array(), height = json::array(), n = json::array(), res = json::array(),
             nres = json::array(), eres = json::array(), sig = json::array(), fail = json::array(),
             lm = json::array(), lr = json::array(), ang = json::array();
        for (size_t j = 0; j < P; ++j) {
            point.push_back(data.pos[j].point);
            ref.push_back(vec3(pos[j].ref));
            height.push_back(pos[j].ref(0));
            n.push_back(pos[j].n);
            res.push_back(vec3(cur.res[j]));
            nres.push_back(vec3(nom.res[j]));
            eres.push_back(vec3(ellE.res[j]));
            V3 s;
            for (int a = 0; a < 3; ++a) s(a) = std::sqrt(cur.var_mean[j](a) + jig(a) * jig(a));
            sig.push_back(vec3(s));
            fail.push_back(bool(vcur.failing[j]));
            lm.push_back(lmean[j]);
            lr.push_back(lres[j]);
            ang.push_back(angle[j]);
        }
        pj["point"] = point;
        pj["ref"] = ref;
        pj["height"] = height;
        pj["n"] = n;
        pj["residual_mm"] = res;
        pj["nominal_residual_mm"] = nres;
        pj["ellipsoid_residual_mm"] = eres;
        pj["sigma_mm"] = sig;
        pj["failing"] = fail;
        pj["lengths_mm"] = lm;
        pj["length_residual_mm"] = lr;
        pj["cable_angle_deg"] = ang;
        out["positions"] = pj;
        json fps = json::object();
        for (size_t a = 0; a < std::min<size_t>(4, cands.size()); ++a) {
            json f = json::array();
            for (auto &v : cands[a].fp) f.push_back(vec3(v));
            fps[cands[a].name] = f;
        }
        out["fingerprints"] = fps;
    }
    out["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fitted = model;
    progress("done", 1.0);
    return true;
}

} // namespace cdm

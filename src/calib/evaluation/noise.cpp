// See noise.h. docs/calibration.md explains each estimate.
#include "calib/evaluation/noise.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace cdm {
namespace diag {

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

namespace {
// An estimate averaged over the plate's lines, a value per row (`rows`) and
// per column (`cols`), each line's mean over its own differences: the mean
// over all lines, and its standard error. Rows share no difference with
// one another, nor columns, so each kind's spread over its lines is an
// honest standard error of its own mean; but a row and a column cross at
// positions they share, so the two means correlate (the spread over all
// the lines as one sample leaves z = estimate / se with a standard
// deviation of 1.15-1.26 on white noise, 1.6 on one 7 x 7 height). Their
// correlation is at most one, so the standard error of the
// mean over all lines is at most the lines-weighted sum of the two kinds'
// (Cauchy-Schwarz): that bound is the one used. With fewer than two lines
// of a kind, the other kind alone. ok: at least 8 lines used.
struct LineEstimate {
    bool ok = false;
    double mean = 0, se = 0;
};
LineEstimate line_estimate(const std::vector<double> &rows, const std::vector<double> &cols) {
    auto of = [](const std::vector<double> &v, double &sum, double &se) {
        const double n = double(v.size());
        sum = 0;
        for (double x : v) sum += x;
        double ss = 0;
        for (double x : v) ss += (x - sum / n) * (x - sum / n);
        se = n >= 2 ? std::sqrt(ss / (n - 1) / n) : INFINITY;
    };
    double sr = 0, ser = 0, sc = 0, sec = 0;
    of(rows, sr, ser);
    of(cols, sc, sec);
    const double nr = double(rows.size()), nc = double(cols.size());
    LineEstimate out;
    if (nr >= 2 && nc >= 2) {
        out.mean = (sr + sc) / (nr + nc);
        out.se = (nr * ser + nc * sec) / (nr + nc);
        out.ok = nr + nc >= 8;
    } else if (nr >= nc) {
        out.mean = nr > 0 ? sr / nr : 0, out.se = ser, out.ok = nr >= 8;
    } else {
        out.mean = sc / nc, out.se = sec, out.ok = nc >= 8;
    }
    return out;
}
} // namespace

// The same second differences at two heights of the same holes share the
// holes' errors and nothing else: the noise, the seating and a height's own
// errors are independent across heights, and a smooth effect nearly cancels
// in each. So E[dd_k dd_k'] = 1.5 s_hole^2, with no noise to subtract. Each
// triple of holes gives the mean of its products over pairs of heights.
// Neighbouring triples along a plate row share holes (their products
// correlate by about 4/9), so the triples are not independent samples: the
// standard error is taken over the plate's rows (the y triples of one row)
// and columns (the z triples of one column), and the estimate is the mean
// over those lines (line_estimate). It is kept only where it is more
// than 3 of those standard errors above zero: a variance component the data
// do not show would cost every fit a block of generalised least squares and
// change nothing.
V3 estimate_hole_std(const Eval &E, const Grid &G) {
    V3 out = V3::Zero();
    if (!G.layered || G.hole_index.size() != E.res.size() || G.cell.size() != E.res.size()) return out;
    std::vector<V3> line_mean[2]; // per plate row (y triples) and column (z triples)
    auto add = [&](const std::vector<int> &cen, const std::vector<std::array<int, 2>> &pr, int across) {
        // A triple of holes: its plate line and its second differences, one per height.
        std::map<std::array<int, 3>, std::pair<long, std::vector<V3>>> by_holes;
        for (size_t k = 0; k < cen.size(); ++k) {
            const int j = cen[k], l = pr[k][0], r = pr[k][1];
            if (!E.ok[size_t(j)] || !E.ok[size_t(l)] || !E.ok[size_t(r)]) continue;
            auto &t = by_holes[{G.hole_index[size_t(j)], G.hole_index[size_t(l)], G.hole_index[size_t(r)]}];
            t.first = G.cell[size_t(j)][size_t(across)];
            t.second.push_back(E.res[size_t(j)] - 0.5 * (E.res[size_t(l)] + E.res[size_t(r)]));
        }
        std::map<long, std::pair<V3, double>> lines;
        for (auto &kv : by_holes) {
            const auto &d = kv.second.second;
            V3 sum = V3::Zero();
            double n = 0;
            for (size_t a = 0; a < d.size(); ++a)
                for (size_t b = a + 1; b < d.size(); ++b) {
                    sum += d[a].cwiseProduct(d[b]);
                    n += 1;
                }
            if (n == 0) continue;
            auto &ln = lines.try_emplace(kv.second.first, V3::Zero(), 0.0).first->second;
            ln.first += sum / n;
            ln.second += 1;
        }
        for (auto &kv : lines) line_mean[across == 1 ? 0 : 1].push_back(kv.second.first / kv.second.second);
    };
    add(G.ycentre, G.ypair, 1); // a row: one z
    add(G.zcentre, G.zpair, 0); // a column: one y
    // y and z only: a hole is drilled off in the plate's plane; along x (the
    // plate's normal, set by the fixture) the plate is flat, and what
    // repeats there at a hole is a smooth error (the nominal model's) that
    // the fit must not weigh as the jig's.
    for (int a = 1; a < 3; ++a) {
        std::vector<double> v[2];
        for (int kind = 0; kind < 2; ++kind)
            for (auto &m : line_mean[kind]) v[kind].push_back(m(a));
        const LineEstimate e = line_estimate(v[0], v[1]);
        if (e.ok && e.mean > 3 * e.se) out(a) = std::sqrt(e.mean / 1.5);
    }
    return out;
}

// Each mean reading's own white error beyond the pots' noise of the mean,
// from the cables' misclosure (Eval::mis): the part of the readings no
// position explains, so that neither the jig's reference nor its error
// enters. A white error of variance t^2 in each reading adds t^2 to every
// misclosure (its direction is a unit vector); a device error adds a
// function of the position, which fourth differences along the plate's rows
// and columns, d = (m_ll - 4 m_l + 6 m_j - 4 m_r + m_rr) / 6 with the
// neighbours' directions aligned with the centre's, cancel to its fourth
// derivative: E[d^2] = noise + (70/36) t^2. (Second differences let a
// ripple left out of the model through: a 0.15 mm ripple of 99 mm read as
// 0.0037 mm on the full jig and 0.015-0.024 mm on half jigs, 15 standard
// errors; fourth differences, under 2.) Differences along one plate line
// share positions, so the standard error is taken over the lines (each
// row's and each column's at a height; line_estimate), as in
// estimate_hole_std; the estimate is kept only where it is more than 3 of those standard errors
// above zero.
ReadingNoise estimate_reading_noise(const Eval &E, const Grid &G) {
    ReadingNoise out;
    if (!G.layered || G.cell.size() != E.res.size() || E.mis.size() != E.res.size()) return out;
    std::map<std::array<long, 3>, std::pair<double, double>> lines; // (kind, height, line) -> sum, count
    auto add = [&](const std::vector<int> &cen, const std::vector<std::array<int, 2>> &pr, long kind, int across) {
        std::map<int, std::array<int, 2>> side; // a centre's neighbours along this axis
        for (size_t k = 0; k < cen.size(); ++k) side[cen[k]] = pr[k];
        constexpr double w[5] = {1, -4, 6, -4, 1};
        for (size_t k = 0; k < cen.size(); ++k) {
            const int j = cen[k], l = pr[k][0], r = pr[k][1];
            const auto il = side.find(l), ir = side.find(r);
            if (il == side.end() || ir == side.end()) continue;
            const int at[5] = {il->second[0], l, j, r, ir->second[1]};
            bool ok = true;
            for (int i : at) ok = ok && E.ok[size_t(i)] && E.mis_var[size_t(i)] > 0;
            if (!ok) continue;
            double d = 0, noise = 0;
            for (int t = 0; t < 5; ++t) {
                const size_t i = size_t(at[t]);
                const double sgn = E.mis_dir[i].dot(E.mis_dir[size_t(j)]) < 0 ? -1 : 1;
                d += w[t] * sgn * E.mis[i];
                noise += w[t] * w[t] * E.mis_var[i];
            }
            d /= 6;
            noise /= 36;
            auto &ln = lines[{kind, long(G.height_index[size_t(j)]), G.cell[size_t(j)][size_t(across)]}];
            ln.first += (d * d - noise) / (70.0 / 36.0);
            ln.second += 1;
        }
    };
    add(G.ycentre, G.ypair, 0, 1);
    add(G.zcentre, G.zpair, 1, 0);
    std::vector<double> v[2];
    for (auto &kv : lines) v[kv.first[0]].push_back(kv.second.first / kv.second.second);
    const LineEstimate e = line_estimate(v[0], v[1]);
    if (!e.ok) return out;
    out.tested = true;
    out.variance = e.mean;
    out.se = e.se;
    if (e.mean > 3 * e.se) out.sigma = std::sqrt(e.mean);
    return out;
}

nlohmann::json reading_noise_json(const ReadingNoise &r) {
    nlohmann::json j = {{"value", r.sigma},
            {"tested", r.tested},
            {"source", r.source},
            {"variance_mm2", r.variance},
            {"se_mm2", r.se},
            {"test", "each mean reading's own white error beyond the pots' noise of the mean (a pot's hysteresis, a "
                     "wiper's offset per approach, a seat that tilts), from the cables' misclosure (the mean readings' "
                     "part no position explains, which neither the reference nor the jig's error enters): its fourth "
                     "differences along the plate's rows and columns, noise subtracted, over 70/36; the standard error "
                     "over the plate's lines (at most the rows' and the columns' each over their own lines, weighted "
                     "by their counts: a row and a column share positions); kept (value > 0) when more than 3 standard errors above zero, and then "
                     "added to every reading's variance"},
            {"note", !r.tested ? "not tested: fewer than 8 lines of the plate (rows and columns at a height) hold "
                                 "five neighbouring positions in a row"
                     : r.sigma > 0 ? "the readings scatter beyond the pots' noise by this much, position to position: "
                                     "every weight, test and the noise floor carry it"
                                   : "none significant"}};
    if (r.source == "re-estimated")
        j["first_estimate"] = {{"variance_mm2", r.first_variance},
                               {"se_mm2", r.first_se},
                               {"note", "on the model fitted first (the user's), whose own error leaks into it; "
                                        "the value above is from the recommended model's misclosure"}};
    return j;
}

void set_jig_noise(FitOptions &fo, const V3 &jig, const V3 &hole) {
    for (int a = 0; a < 3; ++a) {
        fo.hole_sigma(a) = std::clamp(hole(a), 0.0, jig(a));
        fo.jig_sigma(a) = std::sqrt(jig(a) * jig(a) - fo.hole_sigma(a) * fo.hole_sigma(a));
    }
}

} // namespace diag
} // namespace cdm

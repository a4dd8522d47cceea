// See outliers.h. docs/calibration.md, "Outliers", explains the rules.
#include "calib/evaluation/outliers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

double one_cable_chi2(const Eigen::Matrix<double, 3, 4> &Jp, const V3 &d, const V3 &var, int *cable) {
    const V3 w = var.cwiseInverse();
    const double dd = (d.array().square() * w.array()).sum();
    double best = dd;
    if (cable) *cable = -1;
    for (int i = 0; i < 4; ++i) {
        const V3 c = Jp.col(i); // the position's move per mm of cable i's reading
        const double cd = (c.array() * d.array() * w.array()).sum(), cc = (c.array().square() * w.array()).sum();
        if (cc > 0 && dd - cd * cd / cc < best) {
            best = dd - cd * cd / cc;
            if (cable) *cable = i;
        }
    }
    return best;
}

namespace {
// Uniform on [0, n) from the generator's own output (rejection of the
// incomplete last block): the same draws on every standard library.
uint64_t below(std::mt19937_64 &rng, uint64_t n) {
    const uint64_t limit = UINT64_MAX - UINT64_MAX % n;
    uint64_t x;
    do x = rng();
    while (x >= limit);
    return x % n;
}
} // namespace

double join_count_p(const Grid &G, const std::vector<char> &ok, const std::vector<char> &mark) {
    const size_t P = ok.size();
    std::vector<size_t> usable;
    size_t m = 0;
    for (size_t j = 0; j < P; ++j) {
        if (!ok[j]) continue;
        int n = 0;
        for (int k : G.nb[j]) n += ok[size_t(k)] ? 1 : 0;
        if (n < 2 && !mark[j]) continue; // could never be marked by find_outliers
        usable.push_back(j);
        if (mark[j]) ++m;
    }
    auto links = [&](const std::vector<char> &mk) {
        size_t n = 0;
        for (size_t j : usable)
            if (mk[j])
                for (int k : G.nb[j])
                    if (ok[size_t(k)] && mk[size_t(k)]) ++n;
        return n;
    };
    const size_t observed = links(mark);
    if (observed == 0 || m >= usable.size()) return 1.0;
    std::mt19937_64 rng(20261123);
    std::vector<char> mk(P, 0);
    int at_least = 0;
    constexpr int kRelabelings = 999;
    for (int r = 0; r < kRelabelings; ++r) {
        // m of the usable positions, uniformly (a partial Fisher-Yates shuffle)
        std::fill(mk.begin(), mk.end(), 0);
        for (size_t i = 0; i < m; ++i) {
            std::swap(usable[i], usable[i + size_t(below(rng, usable.size() - i))]);
            mk[usable[i]] = 1;
        }
        if (links(mk) >= observed) ++at_least;
    }
    return (1.0 + at_least) / (1.0 + kRelabelings);
}

// The positions whose chi-square chi2[j] is above q and whose residual,
// against the mean of their neighbours' (at least two), is above q too:
// those the model and their neighbours both disown.
static std::vector<Outlier> disowned(const Eval &E, const Grid &G, const V3 &jig, const std::vector<double> &chi2,
                                     double q) {
    std::vector<Outlier> out;
    for (size_t j = 0; j < E.res.size(); ++j) {
        if (!E.ok[j]) continue;
        V3 s2;
        for (int a = 0; a < 3; ++a) s2(a) = E.var_mean[j](a) + jig(a) * jig(a);
        const double c = chi2[j];
        if (!(c > q)) continue;
        V3 mean = V3::Zero(), var = V3::Zero();
        int n = 0;
        for (int k : G.nb[j]) {
            if (!E.ok[size_t(k)]) continue;
            mean += E.res[size_t(k)];
            for (int a = 0; a < 3; ++a) var(a) += E.var_mean[size_t(k)](a) + jig(a) * jig(a);
            ++n;
        }
        if (n < 2) continue; // no neighbours to speak for the smooth part
        mean /= n;
        var /= double(n) * n;
        const double cn = ((E.res[j] - mean).array().square() / (s2 + var).array()).sum();
        if (!(cn > q)) continue;
        Outlier o;
        o.j = j, o.chi2 = c, o.chi2_nb = cn, o.res = E.res[j], o.nb = mean, o.var = s2 + var;
        out.push_back(o);
    }
    return out;
}

std::vector<Outlier> find_outliers(const Eval &E, const Grid &G, const V3 &jig, size_t already, size_t read,
                                   Declined *declined) {
    const size_t P = E.res.size();
    size_t used = 0;
    for (size_t j = 0; j < P; ++j)
        if (E.ok[j]) ++used;
    std::vector<Outlier> out;
    if (used < 3) return out;
    const double q = chi2_isf(0.01 / double(used), 3); // 1 % family-wise, as judge()
    std::vector<double> chi2(P, 0.0), typical;
    for (size_t j = 0; j < P; ++j) {
        if (!E.ok[j]) continue;
        for (int a = 0; a < 3; ++a) chi2[j] += E.res[j](a) * E.res[j](a) / (E.var_mean[j](a) + jig(a) * jig(a));
        typical.push_back(chi2[j]);
    }
    // Only against a model that fits the bulk: the median position's
    // chi-square at most kOutlierBulkRatio times chi2(3)'s median (2.366).
    // A model far from the data leaves a large smooth residual whose
    // curvature no neighbour average follows (edges and corners would look
    // isolated); that is the verdict's to judge, not outliers.
    std::nth_element(typical.begin(), typical.begin() + std::ptrdiff_t(typical.size() / 2), typical.end());
    if (typical[typical.size() / 2] > kOutlierBulkRatio * chi2_isf(0.5, 3)) return out;
    out = disowned(E, G, jig, chi2, q);
    // A few: set aside, unless more than a quarter of them deviate as one
    // cable's reading error would, counting only cables that two or more
    // of them do so on: a reading effect local in cable length (a worn
    // track), which the positions where that cable passes the spot show and
    // their neighbours do not, is no mis-seated probe (set aside, a worn
    // spot 0.25 mm deep loses 5 to 14 of its positions so, with the fits
    // weighing the readings' own scatter). All are then kept: where two
    // cables pass the spot at once the deviation is no single cable's, and
    // setting those aside would cut the signature (of a worn spot's 7 found,
    // 4 deviate as one cable's on two cables, 3 not). One position on a
    // cable is not enough: a reference off by a few standard errors passes
    // the one-cable test whenever it happens to lie near a cable's direction
    // (were one enough, two and three references off by 0.2 mm would all be
    // kept, each time for one of them), and its cable is then any of the
    // four. More (up to kOutlierScatteredFraction of the positions read):
    // only when they look like references off, not like a reading effect or
    // a local structure.
    const double base = double(read > 0 ? read : used);
    const double total = double(already + out.size());
    // Those that deviate as one cable's reading would, on a cable that two
    // or more of them do (`cables` names the cables).
    std::string cables;
    auto one_cable = [&] {
        int count[4] = {0, 0, 0, 0};
        std::vector<int> which(out.size(), -1);
        for (size_t i = 0; i < out.size(); ++i) {
            int c = -1;
            if (one_cable_chi2(E.Jp[out[i].j], out[i].res - out[i].nb, out[i].var, &c) <= chi2_isf(0.01, 2) && c >= 0)
                ++count[c], which[i] = c;
        }
        int n = 0;
        cables.clear();
        for (int c = 0; c < 4; ++c)
            if (count[c] >= 2) n += count[c], cables += (cables.empty() ? "" : ", ") + std::to_string(c + 1);
        return n;
    };
    auto as_cable = [&](int one) {
        return std::to_string(one) + " of " + std::to_string(out.size()) +
               " deviate as one cable's reading error would, two or more on each such cable (" +
               (cables.find(',') == std::string::npos ? "cable " : "cables ") + cables + "): a reading effect";
    };
    if (total <= std::max(1.0, kOutlierMaxFraction * base)) {
        const int one = out.size() >= 2 ? one_cable() : 0;
        if (one > 0 && 4 * one > int(out.size())) {
            if (declined) *declined = Declined{out.size(), as_cable(one)};
            out.clear();
        }
        return out;
    }
    char why[200] = "";
    if (!(kOutlierMaxFraction * base >= 1))
        std::snprintf(why, sizeof why, "a jig of %.0f positions has none to spare", base);
    else if (total > kOutlierScatteredFraction * base)
        std::snprintf(why, sizeof why, "%.0f of %.0f positions: more than 10 %% are not a few bad positions", total, base);
    if (!*why) {
        const int one = one_cable();
        if (one > 0 && 4 * one > int(out.size())) std::snprintf(why, sizeof why, "%s", as_cable(one).c_str());
    }
    if (!*why) {
        std::vector<char> mark(P, 0);
        for (auto &o : out) mark[o.j] = 1;
        const double p = join_count_p(G, E.ok, mark);
        if (p < kOutlierScatterLevel)
            std::snprintf(why, sizeof why, "they cluster on the plate (join count p = %.3g): a local structure", p);
    }
    if (*why) {
        if (declined) *declined = Declined{out.size(), why};
        out.clear();
    }
    return out;
}

} // namespace diag
} // namespace cdm

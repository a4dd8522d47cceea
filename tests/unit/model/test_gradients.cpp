// Every derivative the library computes, against central differences of the
// values it computes (mrcal's test-gradients, for this model): for each
// built-in effect, d reading / d parameter (the fit's automatic
// differentiation) and d reading / d position, at random parameters within
// the simulator's realistic ranges and random positions in the workspace;
// the forward kinematics' d position / d lengths; the fit's full weighted
// residual Jacobian with every effect on at once. A new built-in in
// effects/list.h is picked up from the registry.
//
// Tolerance. A central difference with step h of a function f computed with
// relative rounding error r differs from the derivative by at most
//     h^2 |f'''| / 6          (truncation; f''' bounded near x)
//   + r |f| / h               (rounding of the two evaluations, 2 r|f| / 2h)
// and the automatic derivative itself carries ~ r |f'|. One reading is a
// few dozen floating-point operations on lengths of ~200 mm; each rounds by
// at most eps/2 of a magnitude <= |f|, so r = 32 eps bounds it. |f'''| is
// estimated from a third difference at a 10x larger step,
// (f(x+2H) - 2f(x+H) + 2f(x-H) - f(x-2H)) / (2H^3), whose own rounding only
// makes the bound larger. h is 1e-3 of each parameter's typical magnitude
// (1e-3 mm for positions, 1e-2 mm for lengths): the rounding term then
// stays near 1e-9 of the derivative and truncation far below it.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <random>
#include <setjmp.h>
#include <string>
#include <vector>

#include "calib/fit/fit.h"
#include "model/effect.h"
#include "model/model.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

namespace {

constexpr double kEps = 2.220446049250313e-16;
constexpr double kRound = 32 * kEps;

// f(t) -> n values; checks d f / d t at t = 0 against `ad` (n values).
using Fn = std::function<bool(double t, double *out)>;

// fscale: the magnitude of the terms f is computed from, when f is a small
// difference of large ones (a residual mean - y: the rounding is that of y).
int check(const char *what, const Fn &f, int n, double h, const double *ad, double extra_abs = 0,
          double fscale = 0) {
    const size_t sz = size_t(n);
    std::vector<double> f0(sz), fp(sz), fm(sz), a(sz), b(sz), c(sz), d(sz);
    const double H = 10 * h;
    if (!f(0, f0.data()) || !f(h, fp.data()) || !f(-h, fm.data()) || !f(2 * H, a.data()) || !f(H, b.data()) ||
        !f(-H, c.data()) || !f(-2 * H, d.data())) {
        std::printf("%s: evaluation failed\n", what);
        return 1;
    }
    int bad = 0;
    for (int i = 0; i < n; ++i) {
        const size_t k = size_t(i);
        const double cd = (fp[k] - fm[k]) / (2 * h);
        const double f3 = std::fabs(a[k] - 2 * b[k] + 2 * c[k] - d[k]) / (2 * H * H * H);
        const double fmag =
            std::fmax(fscale, std::fmax(std::fabs(f0[k]), std::fmax(std::fabs(fp[k]), std::fabs(fm[k]))));
        const double tol = h * h * f3 / 6 + kRound * fmag / h + kRound * std::fabs(ad[k]) + extra_abs;
        if (!(std::fabs(cd - ad[k]) <= tol)) {
            std::printf("%s [%d]: automatic %.12g, central difference %.12g, |diff| %.3g > tolerance %.3g\n", what, i,
                        ad[k], cd, std::fabs(cd - ad[k]), tol);
            ++bad;
        }
    }
    return bad;
}

std::mt19937_64 &rng() {
    static std::mt19937_64 r(20261123);
    return r;
}
void random_position(double p[3]) {
    std::uniform_real_distribution<double> ux(30, 90), uyz(-60, 60);
    p[0] = ux(rng());
    p[1] = uyz(rng());
    p[2] = uyz(rng());
}

// Positions as the fit sees them: unit variance, no jig tolerance, so that
// the weights do not depend on the parameters (the fit holds them fixed).
std::vector<PreparedPos> fit_positions(const Model &m, int n) {
    std::vector<PreparedPos> v;
    for (int j = 0; j < n; ++j) {
        PreparedPos pp;
        double r[3], P[3], y[4];
        random_position(r);
        m.jig_to_device(r, P);
        m.readings(P, y);
        pp.ref = Eigen::Vector3d(r[0], r[1], r[2]);
        for (int c = 0; c < 4; ++c) pp.mean(c) = y[c] + 0.01 * (c - 1.5); // a small residual, as after a fit
        pp.var_mean.setOnes();
        pp.cov.setIdentity();
        pp.n = 1;
        v.push_back(pp);
    }
    return v;
}

FitOptions no_jig_tolerance() {
    FitOptions o;
    o.jig_sigma.setZero();
    return o;
}

// Perturbs parameter k of effect e by t (false when it leaves the bounds).
bool with_param(Model &m, size_t e, size_t k, double base, double t) {
    std::vector<double> v = m.effect_params(e);
    v[k] = base + t;
    std::string err;
    return m.set_effect_params(e, v, err);
}

} // namespace

// d reading / d parameter for each built-in acting on the readings, alone in
// the model, at 3 random parameter sets x 5 positions.
static void reading_parameter_gradients(void **) {
    int bad = 0, checked = 0;
    for (const auto &d : all_effects()) {
        if (d->builtin_id < 0 || d->stage == Stage::Position) continue;
        for (uint64_t seed = 1; seed <= 3; ++seed) {
            Model m{DeviceGeometry{}};
            std::string err;
            assert_true(m.add_effect_random(d->name, seed, err));
            const auto pos = fit_positions(m, 5);
            Eigen::VectorXd res;
            Eigen::MatrixXd J;
            assert_true(fit_residual_jacobian(m, pos, no_jig_tolerance(), res, J, err));
            assert_int_equal(J.cols(), int(d->params.size()));
            for (size_t k = 0; k < d->params.size(); ++k) {
                const double base = m.effect_params(0)[k];
                Model mp = m;
                Fn f = [&](double t, double *out) {
                    if (!with_param(mp, 0, k, base, t)) return false;
                    for (size_t j = 0; j < pos.size(); ++j) {
                        double r[3] = {pos[j].ref(0), pos[j].ref(1), pos[j].ref(2)}, P[3];
                        mp.jig_to_device(r, P);
                        if (mp.readings(P, out + 4 * j) != 0) return false;
                    }
                    return true;
                };
                std::vector<double> ad(4 * pos.size());
                for (size_t r = 0; r < ad.size(); ++r) ad[r] = -J(int(r), int(k)); // residual = mean - y
                const std::string what = d->name + "." + d->params[k].name + " seed " + std::to_string(seed);
                bad += check(what.c_str(), f, int(ad.size()), 1e-3 * d->params[k].scale, ad.data());
                ++checked;
            }
        }
    }
    std::printf("%d parameter gradients checked\n", checked);
    assert_true(checked > 0);
    assert_int_equal(bad, 0);
}

// d reading / d position for each built-in alone, and nominal.
static void reading_position_gradients(void **) {
    int bad = 0;
    for (const auto &d : all_effects()) {
        if (d->builtin_id < 0) continue;
        for (uint64_t seed = 1; seed <= 3; ++seed) {
            Model m{DeviceGeometry{}};
            std::string err;
            assert_true(m.add_effect_random(d->name, seed, err));
            for (int j = 0; j < 5; ++j) {
                double p[3], y[4], J[12];
                random_position(p);
                assert_int_equal(m.readings_jacobian(p, 0.0, y, J), 0);
                for (int k = 0; k < 3; ++k) {
                    Fn f = [&](double t, double *out) {
                        double q[3] = {p[0], p[1], p[2]};
                        q[k] += t;
                        return m.readings(q, out) == 0;
                    };
                    double ad[4] = {J[k], J[3 + k], J[6 + k], J[9 + k]};
                    const std::string what = d->name + " d/dP" + std::to_string(k);
                    bad += check(what.c_str(), f, 4, 1e-3, ad);
                }
            }
        }
    }
    assert_int_equal(bad, 0);
}

// A model with every physical built-in on (random realistic parameters) and
// the seed's ellipsoid, as the driver runs it.
static Model full_model(uint64_t seed, bool jig) {
    Model m{DeviceGeometry{}};
    std::string err;
    for (const auto &d : all_effects()) {
        if (d->builtin_id < 0 || d->stage == Stage::Position || (!jig && d->stage == Stage::Jig)) continue;
        assert_true(m.add_effect_random(d->name, seed + uint64_t(d->builtin_id), err));
    }
    return m;
}

// Forward kinematics: d position / d lengths from position() against central
// differences of position(). Gauss-Newton stops when its step is below
// 1e-9 mm; the solution is then within that of the exact one, which adds
// 2e-9 / (2h) to the difference quotient (extra_abs below).
static void forward_kinematics_jacobian(void **) {
    int bad = 0;
    for (int variant = 0; variant < 3; ++variant) {
        Model m{DeviceGeometry{}};
        std::string err;
        if (variant >= 1) m = full_model(40 + uint64_t(variant), false);
        if (variant == 2) assert_true(m.add_effect("ellipsoid", {{"L", 5989.1}, {"M", 2950.2}, {"N", 3092.8}}, err));
        for (int j = 0; j < 8; ++j) {
            double p[3], L[4], q[3], J[12];
            random_position(p);
            assert_int_equal(m.readings(p, L), 0);
            assert_int_equal(m.position(L, 0.0, q, J), 0);
            const double h = 1e-2;
            for (int c = 0; c < 4; ++c) {
                Fn f = [&](double t, double *out) {
                    double l2[4] = {L[0], L[1], L[2], L[3]};
                    l2[c] += t;
                    return m.position(l2, out) == 0;
                };
                double ad[3] = {J[c], J[4 + c], J[8 + c]};
                const std::string what = "position variant " + std::to_string(variant) + " d/dl" + std::to_string(c);
                bad += check(what.c_str(), f, 3, h, ad, 2e-9 / (2 * h));
            }
        }
    }
    assert_int_equal(bad, 0);
}

// The fit's full weighted residual Jacobian (what the NLopt objective uses)
// with every physical effect on, the jig transform included: each column
// against central differences of the residuals.
static void fit_jacobian_full_model(void **) {
    int bad = 0;
    for (uint64_t seed = 7; seed <= 8; ++seed) {
        Model m = full_model(seed * 100, true);
        const auto pos = fit_positions(m, 12);
        double ymax = 0; // the readings the residuals are computed from
        for (auto &pp : pos) ymax = std::fmax(ymax, pp.mean.cwiseAbs().maxCoeff());
        Eigen::VectorXd res;
        Eigen::MatrixXd J;
        std::string err;
        assert_true(fit_residual_jacobian(m, pos, no_jig_tolerance(), res, J, err));
        int col = 0;
        for (size_t e = 0; e < m.effect_count(); ++e) {
            const EffectDesc &d = m.effect_desc(e);
            if (d.stage == Stage::Position) continue;
            for (size_t k = 0; k < d.params.size(); ++k, ++col) {
                const double base = m.effect_params(e)[k];
                Model mp = m;
                Fn f = [&](double t, double *out) {
                    if (!with_param(mp, e, k, base, t)) return false;
                    Eigen::VectorXd r2;
                    Eigen::MatrixXd J2;
                    std::string e2;
                    if (!fit_residual_jacobian(mp, pos, no_jig_tolerance(), r2, J2, e2)) return false;
                    for (int i = 0; i < r2.size(); ++i) out[i] = r2(i);
                    return true;
                };
                std::vector<double> ad(size_t(J.rows()));
                for (int r = 0; r < J.rows(); ++r) ad[size_t(r)] = J(r, col);
                const std::string what = "fit Jacobian " + d.name + "." + d.params[k].name;
                bad += check(what.c_str(), f, int(ad.size()), 1e-3 * d.params[k].scale, ad.data(), 0, ymax);
            }
        }
        assert_int_equal(col, J.cols());
    }
    assert_int_equal(bad, 0);
}

// The fit's weighting (calib/fit/problem.h) is generalised least squares: the
// chi-square equals r' S^-1 r computed densely in raw reading space, r the
// readings' residuals (mean - y) and S, per hole, the block of
// diag(var_mean) + dP diag(jig_sigma^2) dP' per position (its own jig
// error moves its four readings together) plus U U' for the hole's shared
// error, U = dP diag(hole_sigma) stacked over the hole's positions, dP the
// readings' derivative in the jig frame by central differences; and the
// gradient J'r is the dense J' S^-1 r. Holes of one to four positions in a
// shuffled order, and a position in no hole (-1: a block of its own). The
// raw residuals and Jacobian come from the fit with no jig term at all,
// whose whitening is then 1/sqrt(var_mean) = 100 on every reading. dP's
// step, 1e-3 mm, leaves a truncation error near 1e-7 of dP: agreement to
// 1e-5. Each reading weighed alone (the diagonal only) must differ.
static void fit_weighting_is_dense_gls(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    assert_true(m.add_effect_random("exit_pulley", 3, err));
    assert_true(m.add_effect_random("cable_gain", 4, err));
    auto pos = fit_positions(m, 12);
    for (auto &p : pos) p.var_mean.setConstant(1e-4); // 0.01 mm: the jig's share is large
    const std::vector<int> hole = {2, 0, 1, 0, 2, -1, 1, 0, 3, 2, 0, 1};
    FitOptions a;
    a.jig_sigma = Eigen::Vector3d(0.01, 0.02, 0.015);
    a.hole = hole;
    a.hole_sigma = Eigen::Vector3d(0.0, 0.03, 0.04);
    FitOptions b = a; // the raw residuals: no jig term, each reading weighed 1/0.01
    b.hole_sigma.setZero();
    b.jig_sigma.setZero();
    Eigen::VectorXd ra, rb;
    Eigen::MatrixXd Ja, Jb;
    assert_true(fit_residual_jacobian(m, pos, a, ra, Ja, err));
    assert_true(fit_residual_jacobian(m, pos, b, rb, Jb, err)); // position order: no hole model, no grouping
    rb /= 100;
    Jb /= 100;
    const size_t P = pos.size();
    std::vector<Eigen::Matrix<double, 4, 3>> dP(P);
    for (size_t j = 0; j < P; ++j)
        for (int ax = 0; ax < 3; ++ax) {
            double rp[3] = {pos[j].ref(0), pos[j].ref(1), pos[j].ref(2)}, rm[3] = {rp[0], rp[1], rp[2]}, Pp[3], Pm[3],
                   yp[4], ym[4];
            rp[ax] += 1e-3;
            rm[ax] -= 1e-3;
            m.jig_to_device(rp, Pp);
            m.jig_to_device(rm, Pm);
            assert_int_equal(m.readings(Pp, yp), 0);
            assert_int_equal(m.readings(Pm, ym), 0);
            for (int c = 0; c < 4; ++c) dP[j](c, ax) = (yp[c] - ym[c]) / 2e-3;
        }
    // The blocks: each hole's positions, and the -1 position alone.
    std::vector<std::vector<size_t>> blocks;
    for (int h = 0; h <= 3; ++h) {
        blocks.emplace_back();
        for (size_t j = 0; j < P; ++j)
            if (hole[j] == h) blocks.back().push_back(j);
    }
    for (size_t j = 0; j < P; ++j)
        if (hole[j] < 0) blocks.push_back({j});
    const Eigen::Matrix3d Sj = a.jig_sigma.cwiseAbs2().asDiagonal();
    double chi2 = 0, indep = 0;
    Eigen::VectorXd grad = Eigen::VectorXd::Zero(Jb.cols());
    for (auto &bl : blocks) {
        const long m4 = 4 * long(bl.size());
        Eigen::MatrixXd U(m4, 3), Jh(m4, Jb.cols());
        Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m4, m4);
        Eigen::VectorXd r(m4);
        for (size_t i = 0; i < bl.size(); ++i) {
            const long o = 4 * long(i);
            U.block<4, 3>(o, 0) = dP[bl[i]] * a.hole_sigma.asDiagonal();
            S.block<4, 4>(o, o) = Eigen::Matrix4d(pos[bl[i]].var_mean.asDiagonal()) + dP[bl[i]] * Sj * dP[bl[i]].transpose();
            r.segment<4>(o) = rb.segment<4>(4 * long(bl[i]));
            Jh.middleRows(o, 4) = Jb.middleRows(4 * long(bl[i]), 4);
            for (int c = 0; c < 4; ++c) indep += r(o + c) * r(o + c) / S(o + c, o + c);
        }
        S += U * U.transpose();
        const Eigen::VectorXd Sr = S.ldlt().solve(r);
        chi2 += r.dot(Sr);
        grad += Jh.transpose() * Sr;
    }
    const double got = ra.squaredNorm();
    if (std::fabs(got - chi2) > 1e-5 * chi2)
        fail_msg("fit weighting: chi-square %.9g, dense GLS %.9g (each reading alone: %.9g)", got, chi2, indep);
    if (std::fabs(indep - chi2) < 1e-2 * chi2) fail_msg("the correlations changed nothing: %.9g vs %.9g", indep, chi2);
    const Eigen::VectorXd ga = Ja.transpose() * ra;
    if ((ga - grad).norm() > 1e-5 * grad.norm())
        fail_msg("fit weighting: gradient off by %.3g of its norm", (ga - grad).norm() / grad.norm());
    if (std::fabs(model_chi2(m, pos, a) - got) > 1e-9 * got) fail_msg("model_chi2 is not the residuals' chi-square");
}

int main() {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(reading_parameter_gradients),
        cmocka_unit_test(reading_position_gradients),
        cmocka_unit_test(forward_kinematics_jacobian),
        cmocka_unit_test(fit_jacobian_full_model),
        cmocka_unit_test(fit_weighting_is_dense_gls),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}

// See accuracy.h.
#include "calib/evaluation/accuracy.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "model/effect.h"
#include "model/evaluator.h"

namespace cdm {
namespace diag {

namespace {

// The parameters' covariance without the jig's placement, and the
// parameter vector with it at the identity (ref = device frame).
void without_the_jig(const Model &m, const ReadingEvaluator &ev, Eigen::VectorXd &full, Eigen::MatrixXd &C) {
    full = ev.current();
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (ev.offset(e) < 0 || m.effect_desc(e).stage != Stage::Jig) continue;
        const int o = ev.offset(e), n = int(m.effect_desc(e).params.size());
        full.segment(o, n).setZero();
        C.middleRows(o, n).setZero();
        C.middleCols(o, n).setZero();
    }
}

// The levels in x: the fixture heights' mean device-frame x (or five over a
// scattered layout's span), and one past each end.
std::vector<double> x_levels(const std::vector<V3> &dev, const std::vector<PreparedPos> &pos, const Grid &G) {
    std::vector<double> lv;
    int nh = 0;
    for (int h : G.height_index) nh = std::max(nh, h + 1);
    if (G.layered && nh >= 2 && G.height_index.size() == pos.size()) {
        std::vector<double> s(size_t(nh), 0.0), n(size_t(nh), 0.0);
        for (size_t j = 0; j < dev.size(); ++j)
            if (G.height_index[j] >= 0) s[size_t(G.height_index[j])] += dev[j](0), n[size_t(G.height_index[j])] += 1;
        for (int h = 0; h < nh; ++h)
            if (n[size_t(h)] > 0) lv.push_back(s[size_t(h)] / n[size_t(h)]);
        std::sort(lv.begin(), lv.end());
    }
    if (lv.size() < 2) {
        lv.clear();
        double lo = INFINITY, hi = -INFINITY;
        for (const auto &d : dev) lo = std::min(lo, d(0)), hi = std::max(hi, d(0));
        if (!(hi > lo)) return {lo - 10, lo, lo + 10}; // one height: 10 mm past it on each side
        for (int k = 0; k < 5; ++k) lv.push_back(lo + (hi - lo) * k / 4.0);
    }
    const double step = (lv.back() - lv.front()) / double(lv.size() - 1);
    lv.insert(lv.begin(), lv.front() - step);
    lv.push_back(lv.back() + step);
    return lv;
}

nlohmann::json summary(const AccuracyMap &a, bool inside) {
    Acc s[3], r;
    double worst[3] = {0, 0, 0}, rworst = 0;
    for (size_t j = 0; j < a.p.size(); ++j) {
        if (!a.ok[j] || bool(a.inside[j]) != inside) continue;
        for (int k = 0; k < 3; ++k) {
            const double sd = std::sqrt(std::max(0.0, a.cov[j](k, k)));
            s[k].add(sd);
            worst[k] = std::max(worst[k], sd);
        }
        const double r95 = std::sqrt(kChi2Of3At95 * std::max(0.0, a.cov[j].selfadjointView<Eigen::Lower>().eigenvalues().maxCoeff()));
        r.add(r95);
        rworst = std::max(rworst, r95);
    }
    if (r.n == 0) return nullptr;
    auto mean = [](const Acc &x) { return x.s / x.n; };
    return {{"points", size_t(r.n)},
            {"sigma_mm",
             {{"x", {{"mean", mean(s[0])}, {"max", worst[0]}}},
              {"y", {{"mean", mean(s[1])}, {"max", worst[1]}}},
              {"z", {{"mean", mean(s[2])}, {"max", worst[2]}}}}},
            {"radius95_mm", {{"mean", mean(r)}, {"max", rworst}}}};
}

} // namespace

bool position_covariances(const Model &m, const Eigen::MatrixXd &cov, const std::vector<V3> &pts, double t_s,
                          std::vector<Eigen::Matrix3d> &out, std::vector<char> &ok, std::string &err) {
    const ReadingEvaluator ev(m);
    if (cov.rows() != ev.size() || cov.cols() != ev.size()) {
        err = "the covariance has " + std::to_string(cov.rows()) + " rows for the model's " +
              std::to_string(ev.size()) + " fitted parameters";
        return false;
    }
    Eigen::VectorXd full;
    Eigen::MatrixXd C = cov;
    without_the_jig(m, ev, full, C);
    out.assign(pts.size(), Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN()));
    ok.assign(pts.size(), 0);
    if (pts.empty()) return true;
    // Every point in one batch: a user effect on arrays is called once.
    std::vector<double> refs(3 * pts.size()), ts(pts.size(), t_s);
    for (size_t j = 0; j < pts.size(); ++j)
        for (int k = 0; k < 3; ++k) refs[3 * j + size_t(k)] = pts[j](k);
    ReadingEvaluator::Batch b;
    if (!ev.eval_batch(full, pts.size(), refs.data(), ts.data(), true, true, b, &err)) return false;
    for (size_t j = 0; j < pts.size(); ++j) {
        const auto &D = b.dydP[j];
        if (!b.y[j].allFinite() || !b.J[j].allFinite() || !D.allFinite()) continue; // outside its workspace
        // The forward kinematics' sensitivity at an exact solution: the
        // readings' least-squares inverse (Model::position's Gauss-Newton).
        const Eigen::Matrix3d DtD = D.transpose() * D;
        Eigen::LDLT<Eigen::Matrix3d> f(DtD);
        if (f.info() != Eigen::Success || !(f.vectorD().minCoeff() > 0)) continue;
        const Eigen::Matrix<double, 3, 4> A = f.solve(D.transpose());
        const Eigen::Matrix<double, 3, Eigen::Dynamic> G = A * b.J[j];
        out[j] = G * C * G.transpose();
        ok[j] = out[j].allFinite();
    }
    return true;
}

bool accuracy_map(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos, const Grid &G,
                  AccuracyMap &out, std::string &err) {
    out = AccuracyMap();
    if (pos.empty() || rep.cov_by_hole.size() == 0) {
        err = pos.empty() ? "no positions"
                          : "no fitted parameter to propagate (a model of position-space effects alone, or a fit "
                            "without statistics)";
        return false;
    }
    std::vector<V3> dev(pos.size());
    V3 lo = V3::Constant(INFINITY), hi = V3::Constant(-INFINITY);
    for (size_t j = 0; j < pos.size(); ++j) {
        double d[3];
        m.jig_to_device(pos[j].ref.data(), d);
        dev[j] = V3(d[0], d[1], d[2]);
        lo = lo.cwiseMin(dev[j]), hi = hi.cwiseMax(dev[j]);
        out.t_s += pos[j].t_s / double(pos.size()); // mid-session, for effects that drift
    }
    out.levels = x_levels(dev, pos, G);
    out.ny = out.nz = 13; // the plate's span in 8 steps, 2 more past each side
    const V3 span = hi - lo;
    for (double x : out.levels)
        for (int iz = 0; iz < out.nz; ++iz)
            for (int iy = 0; iy < out.ny; ++iy) {
                const double y = lo(1) + span(1) * (iy - 2) / 8.0, z = lo(2) + span(2) * (iz - 2) / 8.0;
                out.p.emplace_back(x, y, z);
                const double tol = 1e-9 * (1 + span.norm());
                out.inside.push_back(x >= out.levels[1] - tol && x <= out.levels[out.levels.size() - 2] + tol &&
                                     iy >= 2 && iy <= 10 && iz >= 2 && iz <= 10);
            }
    return position_covariances(m, rep.cov_by_hole, out.p, out.t_s, out.cov, out.ok, err);
}

nlohmann::json accuracy_json(const AccuracyMap &a) {
    using nlohmann::json;
    json xs = json::array(), ys = json::array(), zs = json::array(), sig = json::array(), r95 = json::array(),
         cov = json::array(), inside = json::array(), placed = json::array();
    for (size_t j = 0; j < a.p.size(); ++j) {
        xs.push_back(a.p[j](0)), ys.push_back(a.p[j](1)), zs.push_back(a.p[j](2));
        inside.push_back(bool(a.inside[j]));
        placed.push_back(bool(a.ok[j]));
        if (!a.ok[j]) {
            sig.push_back(nullptr), r95.push_back(nullptr), cov.push_back(nullptr);
            continue;
        }
        const Eigen::Matrix3d &S = a.cov[j];
        sig.push_back({std::sqrt(std::max(0.0, S(0, 0))), std::sqrt(std::max(0.0, S(1, 1))), std::sqrt(std::max(0.0, S(2, 2)))});
        r95.push_back(std::sqrt(kChi2Of3At95 * std::max(0.0, S.selfadjointView<Eigen::Lower>().eigenvalues().maxCoeff())));
        cov.push_back({S(0, 0), S(1, 1), S(2, 2), S(0, 1), S(0, 2), S(1, 2)});
    }
    return {{"grid", {{"x_mm", xs}, {"y_mm", ys}, {"z_mm", zs}, {"levels_mm", a.levels}, {"ny", a.ny}, {"nz", a.nz}}},
            {"t_s", a.t_s},
            {"sigma_mm", sig},
            {"radius95_mm", r95},
            {"cov_mm2", cov},
            {"inside", inside},
            {"placed", placed},
            {"summary", {{"inside", summary(a, true)}, {"outside", summary(a, false)}}},
            {"method", "the fitted parameters' covariance (the readings' noise, the jig's tolerance and errors, "
                       "inflated by chi2/dof when above 1) propagated to the position to first order: "
                       "A J C J' A', J the readings' derivative in the parameters, A the forward kinematics' "
                       "in the readings; the jig's placement left out, a Position-stage effect's own "
                       "uncertainty not propagated; device frame, at mid-session time"}};
}

nlohmann::json accuracy_map_json(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos,
                                 const Grid &G) {
    AccuracyMap a;
    std::string err;
    if (!accuracy_map(m, rep, pos, G, a, err)) return {{"error", err}};
    return accuracy_json(a);
}

namespace {

// "effect.param" for each of the model's fitted parameters, in
// ReadingEvaluator's order.
std::vector<std::string> fitted_names(const Model &m) {
    std::vector<std::string> v;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        const auto &d = m.effect_desc(e);
        if (d.stage == Stage::Position) continue;
        for (const auto &p : d.params) v.push_back(d.name + "." + p.name);
    }
    return v;
}

} // namespace

nlohmann::json covariance_json(const Model &m, const Eigen::MatrixXd &cov) {
    nlohmann::json rows = nlohmann::json::array();
    for (Eigen::Index i = 0; i < cov.rows(); ++i) {
        nlohmann::json r = nlohmann::json::array();
        for (Eigen::Index k = 0; k < cov.cols(); ++k) r.push_back(cov(i, k));
        rows.push_back(r);
    }
    return {{"parameters", fitted_names(m)},
            {"matrix", rows},
            {"about", "the fitted parameters' covariance, robust to errors a plate hole's positions share (a "
                      "sandwich clustered by hole); what cdm_calibration_position_covariance propagates"}};
}

bool covariance_from_json(const nlohmann::json &j, const Model &m, Eigen::MatrixXd &cov, std::string &err) {
    const std::vector<std::string> names = fitted_names(m);
    if (!j.is_object() || !j.contains("parameters") || !j.contains("matrix") || !j["parameters"].is_array() ||
        !j["matrix"].is_array()) {
        err = "fit.covariance: an object with \"parameters\" and \"matrix\" arrays is expected";
        return false;
    }
    const auto &pj = j["parameters"];
    const size_t n = names.size();
    if (pj.size() != n) {
        err = "fit.covariance: " + std::to_string(pj.size()) + " parameters for the model's " + std::to_string(n);
        return false;
    }
    for (size_t i = 0; i < n; ++i)
        if (!pj[i].is_string() || pj[i].get<std::string>() != names[i]) {
            err = "fit.covariance: parameter " + std::to_string(i) + " is " + pj[i].dump() + ", the model's is \"" +
                  names[i] + "\"";
            return false;
        }
    const auto &mj = j["matrix"];
    cov.resize(Eigen::Index(n), Eigen::Index(n));
    if (mj.size() != n) {
        err = "fit.covariance: the matrix must be " + std::to_string(n) + " x " + std::to_string(n) + ", it has " +
              std::to_string(mj.size()) + " rows";
        return false;
    }
    for (size_t i = 0; i < n; ++i) {
        if (!mj[i].is_array() || mj[i].size() != n) {
            err = "fit.covariance: the matrix must be " + std::to_string(n) + " x " + std::to_string(n);
            return false;
        }
        for (size_t k = 0; k < n; ++k) {
            if (!mj[i][k].is_number() || !std::isfinite(mj[i][k].get<double>())) {
                err = "fit.covariance: matrix[" + std::to_string(i) + "][" + std::to_string(k) + "] is not a finite number";
                return false;
            }
            cov(Eigen::Index(i), Eigen::Index(k)) = mj[i][k].get<double>();
        }
    }
    for (size_t i = 0; i < n; ++i) {
        const auto a = Eigen::Index(i);
        if (cov(a, a) < 0) {
            err = "fit.covariance: matrix[" + std::to_string(i) + "][" + std::to_string(i) + "] (a variance) is negative";
            return false;
        }
        for (size_t k = 0; k < i; ++k) {
            const auto b = Eigen::Index(k);
            if (std::fabs(cov(a, b) - cov(b, a)) > 1e-9 * std::sqrt(cov(a, a)) * std::sqrt(cov(b, b)) + 1e-300) {
                err = "fit.covariance: the matrix is not symmetric at [" + std::to_string(i) + "][" + std::to_string(k) + "]";
                return false;
            }
        }
    }
    // A covariance: no direction of negative variance (beyond round-off of
    // its largest, scaled by the diagonal so units do not matter).
    Eigen::VectorXd d = cov.diagonal().cwiseSqrt();
    for (Eigen::Index i = 0; i < d.size(); ++i) d(i) = d(i) > 0 ? 1.0 / d(i) : 0.0;
    const Eigen::MatrixXd R = d.asDiagonal() * cov * d.asDiagonal();
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(R, Eigen::EigenvaluesOnly).eigenvalues();
    if (ev.size() > 0 && !(ev.minCoeff() >= -1e-9 * std::max(1.0, ev.maxCoeff()))) {
        err = "fit.covariance: the matrix is not a covariance (an eigenvalue of its correlation matrix is " +
              std::to_string(ev.minCoeff()) + ")";
        return false;
    }
    return true;
}

} // namespace diag
} // namespace cdm

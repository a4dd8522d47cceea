// The diagnosis's questions about a model on the data, answered with the
// fit's own problem (problem.h) and without fitting: an effect's
// overlap with the others, the chi-square, the weighted residual and its
// Jacobian; the whitening a fit weighed with it computes.
#include <Eigen/QR>

#include "calib/fit/fit.h"
#include "calib/fit/problem.h"

namespace cdm {

using fit_detail::Problem;

Overlap effect_overlap(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                       const std::string &name) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    Overlap out;
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    if (!pb.residuals(res, &J)) return out;
    auto cols = [&](size_t e) {
        const int o = pb.ev.offset(e), n = int(copy.effect_params(e).size());
        Eigen::MatrixXd C = J.middleCols(o, n);
        for (int k = 0; k < n; ++k) {
            const double nn = C.col(k).norm();
            if (nn > 0) C.col(k) /= nn;
        }
        return C;
    };
    int target = -1;
    for (size_t e = 0; e < copy.effect_count(); ++e)
        if (copy.effect_name(e) == name && pb.ev.offset(e) >= 0) target = int(e);
    if (target < 0) return out;
    const Eigen::MatrixXd Jc = cols(size_t(target));
    const double total = Jc.squaredNorm();
    if (total <= 0) return out;
    auto fraction = [&](const Eigen::MatrixXd &B) {
        if (B.cols() == 0) return 0.0;
        // projection onto span(B) via a rank-revealing QR
        Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(B);
        qr.setThreshold(1e-10);
        const int r = int(qr.rank());
        if (r == 0) return 0.0;
        Eigen::MatrixXd Qm = qr.householderQ() * Eigen::MatrixXd::Identity(B.rows(), r);
        return std::sqrt((Qm.transpose() * Jc).squaredNorm() / total);
    };
    Eigen::MatrixXd all(J.rows(), 0);
    for (size_t e = 0; e < copy.effect_count(); ++e) {
        if (int(e) == target || pb.ev.offset(e) < 0) continue;
        Eigen::MatrixXd B = cols(e);
        out.per_effect.emplace_back(copy.effect_name(e), fraction(B));
        Eigen::MatrixXd tmp(J.rows(), all.cols() + B.cols());
        tmp << all, B;
        all = tmp;
    }
    out.all = fraction(all);
    return out;
}

double model_chi2(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, int *n_obs) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    Eigen::VectorXd res;
    if (n_obs) *n_obs = 4 * int(pb.rows.size());
    // A model whose user effect cannot be evaluated explains nothing.
    if (!pb.profile_fixture() || !pb.residuals(res, nullptr)) return INFINITY;
    return res.squaredNorm();
}

bool fit_residual_jacobian(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                           Eigen::VectorXd &res, Eigen::MatrixXd &J, std::string &err) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    if (!pb.residuals(res, &J)) {
        err = pb.failure;
        return false;
    }
    J = -J; // residual = sqrt(w) * (mean - y)
    return true;
}

bool fit_residual_jacobian_with(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                                const std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> &extra,
                                Eigen::VectorXd &res, Eigen::MatrixXd &J, Eigen::MatrixXd &X, std::string &err) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    if (!pb.residuals(res, &J)) {
        err = pb.failure;
        return false;
    }
    J = -J;
    const long k = extra.empty() ? 0 : extra[0].cols();
    X.resize(res.size(), k);
    for (size_t r = 0; r < pb.rows.size(); ++r) {
        const auto &e = extra[size_t(pb.rows[r])];
        X.block(4 * long(r), 0, 4, k) = pb.wh[r].triangularView<Eigen::Lower>() * e;
    }
    Eigen::VectorXd zero = Eigen::VectorXd::Zero(res.size());
    pb.decorrelate(zero, &X);
    return true;
}

std::shared_ptr<const FitWeights> fit_weights(const Model &weigh, const std::vector<PreparedPos> &pos,
                                              const FitOptions &opt) {
    Model wm = weigh;
    FitOptions wo = opt;
    wo.weigh_with = nullptr;
    wo.weights = nullptr;
    wo.hold.clear();
    Problem wp(wm, pos, wo);
    auto w = std::make_shared<FitWeights>();
    w->wh = std::move(wp.wh);
    w->holes = std::move(wp.holes);
    w->rows = wp.rows;
    w->failure = wp.failure;
    return w;
}

} // namespace cdm

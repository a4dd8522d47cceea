// See problem.h (fit_detail::clustered_covariance).
#include <algorithm>
#include <vector>

#include "calib/fit/problem.h"

namespace cdm::fit_detail {

// The parameters' covariance robust to errors a plate hole's positions
// share beyond the noise model (a sandwich, clustered by hole): C M C, C
// the model's covariance (gauge and prior in it) and M the sum over the
// holes of each one's score s = J' res (its rows), outer-multiplied, plus
// the prior's precision. When the noise model is right, E[M] is the
// Hessian and this is C; when a hole's positions share an error the
// weights leave out (a hole error the plate's test did not find), its
// scores add up and this is larger. A position in no hole (or without a
// hole list) is a cluster of its own. Scaled by G / (G - 1) for the G
// clusters' own scatter (the CR1 correction).
Eigen::MatrixXd clustered_covariance(const Problem &pb, const Eigen::MatrixXd &C, const Eigen::MatrixXd &J,
                                     const Eigen::VectorXd &res) {
    const int n = pb.n_params();
    const bool holes = pb.opt.hole.size() == pb.pos.size();
    // cluster of each row: its hole, or a cluster of its own
    std::vector<int> cl(pb.rows.size());
    int nh = 0;
    for (size_t r = 0; r < pb.rows.size(); ++r) nh = std::max(nh, holes ? pb.opt.hole[size_t(pb.rows[r])] + 1 : 0);
    int clusters = nh;
    for (size_t r = 0; r < pb.rows.size(); ++r) {
        const int h = holes ? pb.opt.hole[size_t(pb.rows[r])] : -1;
        cl[r] = h >= 0 ? h : clusters++;
    }
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, clusters);
    for (size_t r = 0; r < pb.rows.size(); ++r)
        S.col(cl[r]).noalias() += J.middleRows(4 * long(r), 4).transpose() * res.segment(4 * long(r), 4);
    int used = 0; // holes with a position in the fit
    for (int c = 0; c < clusters; ++c) used += S.col(c).any() ? 1 : 0;
    Eigen::MatrixXd M = S * S.transpose();
    if (used > 1) M *= double(used) / double(used - 1);
    for (int a = 0; a < n; ++a) M(a, a) += 1.0 / (pb.prior_sd(a) * pb.prior_sd(a));
    const Eigen::MatrixXd V = C * M * C;
    return 0.5 * (V + V.transpose()); // symmetric to the last bit, as a covariance file is checked
}

} // namespace cdm::fit_detail

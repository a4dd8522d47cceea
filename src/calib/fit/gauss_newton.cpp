// See problem.h (fit_detail::bounded_gauss_newton): the Gauss-Newton
// step within the parameters' box, shared by fit_model (optimiser.cpp) and the
// fixture offsets' profile (Problem::profile_fixture).
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "calib/fit/problem.h"

namespace cdm {
// (problem.h says what it solves: Problem::profile_fixture uses it too.)
namespace fit_detail {

BoundedStep bounded_gauss_newton(const Eigen::MatrixXd &H, const Eigen::VectorXd &g, const Eigen::VectorXd &x0,
                                 const Eigen::MatrixXd &Q, const Eigen::VectorXd &lo, const Eigen::VectorXd &hi) {
    const int n = int(H.cols());
    constexpr double kActive = 1e-9;
    struct Con {
        int a;
        double s, bound; // s * (x0(a) + Q.row(a) u - bound) <= 0
    };
    std::vector<Con> all;
    for (int a = 0; a < int(x0.size()); ++a) {
        if (Q.row(a).norm() == 0) continue; // fixed by the gauge
        all.push_back({a, -1.0, lo(a)});
        all.push_back({a, +1.0, hi(a)});
    }
    std::vector<char> in(all.size(), 0);
    for (size_t c = 0; c < all.size(); ++c)
        in[c] = all[c].s * (x0(all[c].a) - all[c].bound) >= -kActive;
    BoundedStep st;
    st.u = Eigen::VectorXd::Zero(n);
    // After a full step (no bound in the way) u is the minimum on the working
    // set: the next iteration goes straight to the multipliers. Testing the
    // recomputed step's length instead fails on badly scaled problems
    // (parameters in mm, rad and 1/mm; cond(H) up to 1e12), where that step
    // is round-off of size eps cond(H) |u|: the loop creeps on to its budget
    // and the fit goes to SLSQP without a Gauss-Newton step (1-4 times per
    // diagnosis).
    bool on_minimum = false;
    for (int it = 0; it < 4 * n + 20; ++it) {
        std::vector<size_t> w;
        for (size_t c = 0; c < all.size(); ++c)
            if (in[c]) w.push_back(c);
        Eigen::MatrixXd A(int(w.size()), n); // the working set's constraint gradients
        for (size_t k = 0; k < w.size(); ++k) A.row(int(k)) = all[w[k]].s * Q.row(all[w[k]].a);
        Eigen::MatrixXd N; // a basis of the directions that keep them
        if (w.empty()) {
            N = Eigen::MatrixXd::Identity(n, n);
        } else {
            Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
            svd.setThreshold(1e-12);
            N = svd.matrixV().rightCols(n - int(svd.rank()));
        }
        const Eigen::VectorXd r = H * st.u + g; // the model's gradient at u
        Eigen::VectorXd p = Eigen::VectorXd::Zero(n);
        if (N.cols() > 0 && !on_minimum) p = -N * (N.transpose() * H * N).ldlt().solve(N.transpose() * r);
        // Whether p gains anything, scale-free: the decrease it promises.
        const double gain = -(r.dot(p) + 0.5 * p.dot(H * p));
        if (on_minimum || !(gain > 1e-15 * (1.0 + std::fabs(g.dot(st.u) + 0.5 * st.u.dot(H * st.u))))) {
            on_minimum = false;
            // Stationary on the working set: a constraint with a negative
            // multiplier (A' lambda = -r, lambda >= 0) is left.
            if (w.empty()) {
                st.kkt = true;
                break;
            }
            const Eigen::VectorXd lam = A.transpose().completeOrthogonalDecomposition().solve(-r);
            int worst = -1;
            double most = -1e-10 * (1.0 + r.norm());
            for (int k = 0; k < int(w.size()); ++k)
                if (lam(k) < most) {
                    most = lam(k);
                    worst = k;
                }
            if (worst < 0) {
                st.kkt = true;
                break;
            }
            in[w[size_t(worst)]] = 0;
            continue;
        }
        // Step along p up to the first bound outside the working set.
        double alpha = 1.0;
        int blocking = -1;
        for (size_t c = 0; c < all.size(); ++c) {
            if (in[c]) continue;
            const double rate = all[c].s * Q.row(all[c].a).dot(p);
            if (rate <= 0) continue;
            const double slack = -all[c].s * (x0(all[c].a) + Q.row(all[c].a).dot(st.u) - all[c].bound);
            const double t = std::max(0.0, slack) / rate;
            if (t < alpha) {
                alpha = t;
                blocking = int(c);
            }
        }
        st.u += alpha * p;
        if (blocking >= 0)
            in[size_t(blocking)] = 1;
        else
            on_minimum = true;
    }
    st.pred = -(g.dot(st.u) + 0.5 * st.u.dot(H * st.u));
    return st;
}

} // namespace fit_detail

} // namespace cdm

// Forward kinematics and reading Jacobians over many positions at once, for
// models with a user effect that works on arrays (cdm_effect_def.apply_batch):
// the diagnosis solves every jig position of every model it evaluates, and an
// effect written in an interpreted language pays per call, not per position.
// The arithmetic is model_position.cpp's (the shared pieces are declared in
// model_impl.h); only the order of the user effects' calls differs. Not the
// haptic path: this allocates.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "model/model_impl.h"
#include "model/triangulate.h"

namespace cdm {

namespace {

// Each point's readings and their central differences in position, as
// readings_and_jacobian (model_position.cpp) makes them through user effects:
// 7 rows per point, the point then +h and -h on each coordinate.
constexpr size_t kRowsPerPoint = 7;

struct Stencil {
    std::vector<double> P, T, Y; // rows x 3, rows, rows x 4
};

// readings_rows with a geometry-aware user effect in the model: the Path
// stage row by row, the path's user effects over every row, the Transfer
// stage row by row, the readings' user effects over every row.
bool readings_rows_geom(const Model::Impl &I, size_t rows, const double *P, const double *T, double *Y) {
    std::vector<double> len(4 * rows), scratch(user_scratch_size(rows));
    std::vector<CableFrame> F(rows);
    auto sample = [&](size_t r) {
        Sample<double> s;
        for (int k = 0; k < 3; ++k) s.P[k] = P[3 * r + size_t(k)];
        s.t_s = T[r];
        return s;
    };
    for (size_t r = 0; r < rows; ++r) I.path_frame(sample(r), &len[4 * r], F[r]);
    const UserRows ur{rows, P, T, F.data()};
    auto stage = [&](bool on_path, double *v) {
        for (const auto &e : I.effects)
            if (e.desc->stage == Stage::User && e.desc->on_path == on_path &&
                call_user_effect(*e.desc, e.p.data(), ur, v, scratch.data()) != 0)
                return false;
        return true;
    };
    if (!stage(true, len.data())) return false;
    for (size_t r = 0; r < rows; ++r) I.transfer_of(sample(r), &len[4 * r], &Y[4 * r]);
    return stage(false, Y);
}

// The readings at `rows` points (P: rows x 3, T: rows) into Y (rows x 4):
// the built-in stages row by row, then each user effect in the model's order
// over every row in one apply_batch call (apply per row for one without it),
// as Model::readings applies them one point at a time. False when a user
// effect returns non-zero (on which row is not known).
bool readings_rows(const Model::Impl &I, size_t rows, const double *P, const double *T, double *Y) {
    if (I.lay.has_geom) return rows == 0 || readings_rows_geom(I, rows, P, T, Y);
    for (size_t r = 0; r < rows; ++r) {
        Sample<double> s;
        for (int k = 0; k < 3; ++k) s.P[k] = P[3 * r + size_t(k)];
        s.t_s = T[r];
        I.builtin_readings(s, &Y[4 * r]);
    }
    for (const auto &e : I.effects) {
        const EffectDesc &d = *e.desc;
        if (d.stage != Stage::User) continue;
        if (d.apply_batch) {
            if (rows > 0 && d.apply_batch(d.user, e.p.data(), rows, P, Y) != 0) return false;
            continue;
        }
        for (size_t r = 0; r < rows; ++r)
            if (d.apply(d.user, e.p.data(), &P[3 * r], &Y[4 * r]) != 0) return false;
    }
    return true;
}

// The readings and 4x3 Jacobians at m points (X: m x 3, T: m): every point's
// stencil rows in one readings_rows.
bool stencil(const Model::Impl &I, size_t m, const double *X, const double *T, Stencil &S) {
    const size_t rows = kRowsPerPoint * m;
    S.P.resize(3 * rows);
    S.T.resize(rows);
    S.Y.resize(4 * rows);
    const double h = kFkPositionStep;
    for (size_t a = 0; a < m; ++a) {
        for (size_t r = 0; r < kRowsPerPoint; ++r) {
            double *P = &S.P[3 * (kRowsPerPoint * a + r)];
            for (int k = 0; k < 3; ++k) P[k] = X[3 * a + size_t(k)];
            if (r > 0) P[(r - 1) / 2] += (r % 2 == 1) ? h : -h; // as xp[k] += h, xm[k] -= h
            S.T[kRowsPerPoint * a + r] = T[a];
        }
    }
    return readings_rows(I, rows, S.P.data(), S.T.data(), S.Y.data());
}

// stencil() over m points, and where a user effect fails on one of them,
// each point's rows alone (one call over its 7 rows; rows are independent,
// so a point fails alone exactly when it fails in the whole): bad[a] = 1
// for the points that fail then. The only case that calls an effect with
// fewer rows than the points' count.
void stencil_each(const Model::Impl &I, size_t m, const double *X, const double *T, Stencil &S,
                  std::vector<char> &bad) {
    bad.assign(m, 0);
    if (stencil(I, m, X, T, S)) return;
    Stencil one;
    for (size_t a = 0; a < m; ++a) {
        if (!stencil(I, 1, X + 3 * a, T + a, one)) {
            bad[a] = 1;
            continue;
        }
        std::copy(one.Y.begin(), one.Y.end(), S.Y.begin() + std::ptrdiff_t(4 * kRowsPerPoint * a));
    }
}

// Point a's readings and Jacobian from the stencil's rows.
void point(const Stencil &S, size_t a, Eigen::Matrix<double, 4, 1> &y, Eigen::Matrix<double, 4, 3> &J) {
    const double *Y = &S.Y[4 * kRowsPerPoint * a];
    const double h = kFkPositionStep;
    for (int i = 0; i < 4; ++i) y(i) = Y[i];
    for (int k = 0; k < 3; ++k)
        for (int i = 0; i < 4; ++i) J(i, k) = (Y[4 * (1 + 2 * k) + i] - Y[4 * (2 + 2 * k) + i]) / (2 * h);
}

} // namespace

bool Model::has_batch_user() const {
    for (const auto &e : impl_->effects)
        if (e.desc->stage == Stage::User && (e.desc->apply_batch || e.desc->apply_geom)) return true;
    return false;
}

void Model::readings_at(size_t n, const double *p, const double *t_s, double *out, int *status) const {
    if (has_batch_user() && readings_rows(*impl_, n, p, t_s, out)) {
        for (size_t j = 0; j < n; ++j) status[j] = 0;
        return;
    }
    // No effect to batch, or a batch call failed: each point alone.
    for (size_t j = 0; j < n; ++j) status[j] = readings(p + 3 * j, t_s[j], out + 4 * j);
}

void Model::readings_jacobians(size_t n, const double *p, const double *t_s, double *out, double *dr_dp,
                               int *status) const {
    if (!has_batch_user()) {
        for (size_t j = 0; j < n; ++j)
            status[j] = readings_jacobian(p + 3 * j, t_s[j], out + 4 * j, dr_dp + 12 * j);
        return;
    }
    Stencil S;
    std::vector<char> bad;
    stencil_each(*impl_, n, p, t_s, S, bad);
    Eigen::Matrix<double, 4, 1> y;
    Eigen::Matrix<double, 4, 3> J;
    for (size_t j = 0; j < n; ++j) {
        status[j] = -1;
        if (bad[j]) continue;
        point(S, j, y, J);
        for (int i = 0; i < 4; ++i) {
            out[4 * j + size_t(i)] = y(i);
            for (int k = 0; k < 3; ++k) dr_dp[12 * j + size_t(3 * i + k)] = J(i, k);
        }
        status[j] = 0;
    }
}

void Model::positions(size_t n, const double *lengths, const double *t_s, double *p, int *status) const {
    const Impl &m = *impl_;
    if (!has_batch_user() || !m.lay.reading_effects) {
        for (size_t j = 0; j < n; ++j) status[j] = position(lengths + 4 * j, t_s[j], p + 3 * j, nullptr);
        return;
    }
    // position()'s start: the triangulation, or eq. (1)-(2) at mid-workspace
    // height where the nominal spheres do not meet.
    std::vector<double> x(3 * n);
    std::vector<size_t> active, next;
    for (size_t j = 0; j < n; ++j) {
        status[j] = -1;
        const double *l = lengths + 4 * j;
        if (!(std::isfinite(l[0]) && std::isfinite(l[1]) && std::isfinite(l[2]) && std::isfinite(l[3]))) continue;
        if (!triangulate(m.g, l, &x[3 * j])) fk_fallback_start(m.g, l, &x[3 * j]);
        active.push_back(j);
    }
    // Gauss-Newton in lockstep: each iteration evaluates the positions still
    // iterating together; each leaves as position() would return.
    Stencil S;
    std::vector<char> bad;
    std::vector<double> X, T;
    Eigen::Matrix<double, 4, 1> y;
    Eigen::Matrix<double, 4, 3> J;
    for (int it = 0; it < kFkIterations && !active.empty(); ++it) {
        X.resize(3 * active.size());
        T.resize(active.size());
        for (size_t a = 0; a < active.size(); ++a) {
            for (int k = 0; k < 3; ++k) X[3 * a + size_t(k)] = x[3 * active[a] + size_t(k)];
            T[a] = t_s[active[a]];
        }
        // Where a user effect fails at a position, position() returns -1.
        stencil_each(m, active.size(), X.data(), T.data(), S, bad);
        next.clear();
        for (size_t a = 0; a < active.size(); ++a) {
            const size_t j = active[a];
            if (bad[a]) continue;
            double *xj = &x[3 * j];
            point(S, a, y, J);
            const int st = fk_step(lengths + 4 * j, y, J, xj);
            if (st == 0) next.push_back(j);
            if (st <= 0) continue; // still iterating, or failed (status stays -1)
            // Converged: position()'s checks and the Position-stage corrections.
            if (!(xj[0] > 0) || !std::isfinite(xj[0] + xj[1] + xj[2])) continue;
            if (!fk_correct(m, xj, nullptr)) continue;
            if (!std::isfinite(xj[0] + xj[1] + xj[2])) continue;
            for (int k = 0; k < 3; ++k) p[3 * j + size_t(k)] = xj[k];
            status[j] = 0;
        }
        active.swap(next);
    }
    // Those still in `active` did not converge in kFkIterations: -1.
}

} // namespace cdm

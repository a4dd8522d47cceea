// The measurement model of the master: nominal geometry (the seed paper's
// a, b, m) plus physical effects switched on by name. One class serves the
// simulator's truth, a fitted calibration and the driver's run-time forward
// kinematics.
//
// Frames: device frame, cable plane y-z, x out of the plane. Cable numbering
// as in the seed (docs/calibration.md): anchors (0,+a,-b) (0,+a,+b) (0,-a,-b)
// (0,-a,+b), holder corners offset by (0, +-m/2, +-m/2) with the same signs.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <utility>

namespace cdm {

// Nominal device description (device JSON: {"a_mm":..,"b_mm":..,"m_mm":..},
// optional "exit_axis": [[x,y,z] x4], "jig": {...}).
struct DeviceGeometry {
    double a_mm = 150.0; // project default (the seed does not give it)
    double b_mm = 150.0;
    double m_mm = 30.0;
    std::array<std::array<double, 3>, 4> exit_axis{{{1, 0, 0}, {1, 0, 0}, {1, 0, 0}, {1, 0, 0}}};

    std::array<double, 3> anchor(int i) const;      // nominal exit point of cable i (0..3)
    std::array<double, 3> holder(int i) const;      // nominal holder corner offset of cable i
    static constexpr double sy[4] = {+1, +1, -1, -1};
    static constexpr double sz[4] = {-1, +1, -1, +1};
};

// The seed's triangulation, eq. (1)-(3) with the digest's geometric eq. (3).
// Exact inverse of the ideal geometry. Returns false (and leaves p alone) when
// the four spheres do not meet (a negative square root) or any input is not
// finite.
bool triangulate(const DeviceGeometry &g, const double lengths[4], double p[3]);

// Ideal cable lengths at holder centre p (nominal geometry, no effects).
void nominal_lengths(const DeviceGeometry &g, const double p[3], double lengths[4]);

class Model; // model/model_impl: geometry + effects with parameters
struct EffectDesc; // model/effect.h

// Parameter values by name, for add_effect.
using ParamValues = std::vector<std::pair<std::string, double>>;

// Shared, immutable once built: the driver swaps whole models.
using ModelPtr = std::shared_ptr<const Model>;

class Model {
public:
    explicit Model(const DeviceGeometry &g);
    ~Model();
    Model(const Model &);
    Model &operator=(const Model &);

    const DeviceGeometry &geometry() const;

    // Effects in the model, in evaluation order, with parameter values.
    size_t effect_count() const;
    const std::string &effect_name(size_t i) const;
    // Adds an effect (built-in or user-registered) with its parameters at
    // their start values, or the given values (by parameter name). False +
    // err on an unknown effect or parameter, or a non-finite value.
    bool add_effect(const std::string &name, const ParamValues &params, std::string &err);
    // Effect i's description and parameter values (effect_desc(i).params order).
    const EffectDesc &effect_desc(size_t i) const;
    const std::vector<double> &effect_params(size_t i) const;
    // Replaces effect i's parameter values; false + err when the size is
    // wrong or a value is non-finite or outside the parameter's bounds.
    bool set_effect_params(size_t i, const std::vector<double> &v, std::string &err);
    bool has_effect(const std::string &name) const;
    // Adds an effect with parameters drawn at random within the realistic
    // ranges its doc states (the simulator's hidden effects).
    bool add_effect_random(const std::string &name, uint64_t seed, std::string &err);

    // Maps a jig reference position into the device frame: identity unless
    // the model has `jig_misalignment`.
    void jig_to_device(const double ref[3], double out[3]) const;

    // Predicted pot readings (mm, nominal scale) at holder centre p, device
    // frame, at acquisition time t_s (s; effects that drift in time read
    // it). Returns 0, or -1 when a user effect's apply returned non-zero
    // (out is then not to be used). Does not allocate for built-in effects.
    int readings(const double p[3], double out[4]) const { return readings(p, 0.0, out); }
    int readings(const double p[3], double t_s, double out[4]) const;
    // The readings and their derivatives d reading_i / d p_k (4x3,
    // row-major): automatic differentiation for the built-ins, central
    // differences through user effects. Same return as readings().
    int readings_jacobian(const double p[3], double t_s, double out[4], double dr_dp[12]) const;

    // Forward kinematics: the position whose predicted readings best match
    // `lengths` (Gauss-Newton from the triangulation). Returns 0, or -1 when
    // there is no real solution, no convergence or a user effect's apply
    // failed (p untouched). dp_dl, when not null, receives d p / d lengths
    // (3x4, row-major) at the solution. Does not allocate for built-in
    // effects.
    int position(const double lengths[4], double p[3]) const { return position(lengths, 0.0, p, nullptr); }
    int position(const double lengths[4], double t_s, double p[3], double dp_dl[12]) const;

    // Over n points or positions at once (row-major arrays, one row each;
    // status[j]: what the one-point function returns for row j):
    // readings_at is readings() (p n x 3, out n x 4), positions is
    // position() without dp_dl (lengths n x 4, p n x 3, a row untouched
    // where -1), readings_jacobians is readings_jacobian() (out n x 4,
    // dr_dp n x 12). When a user effect of the model works on arrays
    // (has_batch_user), each user effect is called once over every row:
    // readings_at once, readings_jacobians once with each point's
    // central-difference steps as rows, positions once per Gauss-Newton
    // iteration over the positions still iterating (lockstep). Same start,
    // steps, convergence test and failures per position as position(), whose
    // results they reproduce (to the last bit when apply_batch computes a
    // row as apply does). When a batch call fails, the points it covered
    // are redone one at a time (a position solve: that iteration's rows of
    // each, in one call per point), so a failure stays the failing point's
    // own.
    // Otherwise the one-point functions at each row. They allocate: not for
    // the haptic path.
    bool has_batch_user() const;
    void readings_at(size_t n, const double *p, const double *t_s, double *out, int *status) const;
    void positions(size_t n, const double *lengths, const double *t_s, double *p, int *status) const;
    void readings_jacobians(size_t n, const double *p, const double *t_s, double *out, double *dr_dp,
                            int *status) const;

    // Position-space correction of the seed's ellipsoid (eq. 4), if the
    // model has the `ellipsoid` effect; applied inside position().
    bool is_nominal() const;

    struct Impl; // model_impl.h, private to src/model

private:
    std::unique_ptr<Impl> impl_;
};

} // namespace cdm

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
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace cdm {

// Nominal device description (device JSON: {"a_mm":..,"b_mm":..,"m_mm":..},
// optional "exit_axis": [[x,y,z] x4], "pulley_radius_mm", "jig": {...}).
struct DeviceGeometry {
    double a_mm = 150.0; // project default (the seed does not give it)
    double b_mm = 150.0;
    double m_mm = 30.0;
    std::array<std::array<double, 3>, 4> exit_axis{{{1, 0, 0}, {1, 0, 0}, {1, 0, 0}, {1, 0, 0}}};
    double pulley_radius_mm = 5.0; // starting value of exit_pulley's radius

    std::array<double, 3> anchor(int i) const;      // nominal exit point of cable i (0..3)
    std::array<double, 3> holder(int i) const;      // nominal holder corner offset of cable i
    static constexpr double sy[4] = {+1, +1, -1, -1};
    static constexpr double sz[4] = {-1, +1, -1, +1};
};

// Parses JSON text; on a syntax error returns false with `err` naming
// source:line:column.
bool parse_json_text(const std::string &text, const std::string &source, nlohmann::json &out, std::string &err);

// Parses a device description. On error returns false and sets `err` to a
// message naming `source` and, for JSON syntax errors, the line and column.
bool parse_device_json(const std::string &text, const std::string &source, DeviceGeometry &out,
                       std::string &err);
nlohmann::json device_to_json(const DeviceGeometry &g);

// The seed's triangulation, eq. (1)-(3) with the digest's geometric eq. (3).
// Exact inverse of the ideal geometry. Returns false (and leaves p alone) when
// the four spheres do not meet (a negative square root) or any input is not
// finite.
bool triangulate(const DeviceGeometry &g, const double lengths[4], double p[3]);

// Ideal cable lengths at holder centre p (nominal geometry, no effects).
void nominal_lengths(const DeviceGeometry &g, const double p[3], double lengths[4]);

struct EffectDesc; // model/effect.h
class Model; // model/model_impl: geometry + effects with parameters

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
    // zero (or the given values, by parameter name). False + err on unknown
    // name or parameter.
    bool add_effect(const std::string &name, const nlohmann::json &params, std::string &err);
    bool has_effect(const std::string &name) const;
    // Contract accessors (docs: /work/notes/common.md); the effects branch
    // owns the real ones, these are minimal bodies for the diagnosis.
    using ParamValues = std::vector<std::pair<std::string, double>>;
    bool add_effect(const std::string &name, const ParamValues &params, std::string &err);
    const EffectDesc &effect_desc(size_t i) const;
    const std::vector<double> &effect_params(size_t i) const; // in effect_desc(i).params order
    bool set_effect_params(size_t i, const std::vector<double> &v, std::string &err);
    // Adds an effect with parameters drawn at random within the realistic
    // ranges its doc states (the simulator's hidden effects).
    bool add_effect_random(const std::string &name, uint64_t seed, std::string &err);

    // Maps a jig reference position into the device frame: identity unless
    // the model has `jig_misalignment`.
    void jig_to_device(const double ref[3], double out[3]) const;

    // Predicted pot readings (mm, nominal scale) at holder centre p, device
    // frame. Does not allocate for built-in effects.
    void readings(const double p[3], double out[4]) const;

    // Forward kinematics: the position whose predicted readings best match
    // `lengths` (Gauss-Newton from the triangulation). Returns 0, or -1 when
    // there is no real solution or no convergence (p untouched). Does not
    // allocate for built-in effects.
    int position(const double lengths[4], double p[3]) const;

    // Position-space correction of the seed's ellipsoid (eq. 4), if the
    // model has the `ellipsoid` effect; applied inside position().
    bool is_nominal() const;

    // Calibration JSON: {"format":"cdm-calibration","version":1,
    //   "device":{...},"effects":[{"name":..,"params":{..}}], ...}
    nlohmann::json to_json() const;
    static bool from_json(const nlohmann::json &j, const std::string &source, Model &out,
                          std::string &err);

    struct Impl;
    Impl &impl();
    const Impl &impl() const;

private:
    std::unique_ptr<Impl> impl_;
};

} // namespace cdm

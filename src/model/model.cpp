// Temporary nominal-only model; the effect machinery replaces it.
#include "model/model.h"

namespace cdm {
struct Model::Impl {
    DeviceGeometry g;
};
Model::Model(const DeviceGeometry &g) : impl_(new Impl{g}) {}
Model::~Model() = default;
Model::Model(const Model &o) : impl_(new Impl(*o.impl_)) {}
Model &Model::operator=(const Model &o) { *impl_ = *o.impl_; return *this; }
const DeviceGeometry &Model::geometry() const { return impl_->g; }
size_t Model::effect_count() const { return 0; }
const std::string &Model::effect_name(size_t) const { static std::string s; return s; }
bool Model::add_effect(const std::string &name, const nlohmann::json &, std::string &err) { err = "unknown effect " + name; return false; }
bool Model::add_effect_random(const std::string &name, uint64_t, std::string &err) { err = "unknown effect " + name; return false; }
bool Model::has_effect(const std::string &) const { return false; }
void Model::jig_to_device(const double ref[3], double out[3]) const { for (int i = 0; i < 3; ++i) out[i] = ref[i]; }
void Model::readings(const double p[3], double out[4]) const { nominal_lengths(impl_->g, p, out); }
int Model::position(const double l[4], double p[3]) const { return triangulate(impl_->g, l, p) ? 0 : -1; }
bool Model::is_nominal() const { return true; }
nlohmann::json Model::to_json() const { return {{"format", "cdm-calibration"}, {"version", 1}, {"device", device_to_json(impl_->g)}, {"effects", nlohmann::json::array()}}; }
bool Model::from_json(const nlohmann::json &, const std::string &, Model &, std::string &err) { err = "not yet"; return false; }
Model::Impl &Model::impl() { return *impl_; }
const Model::Impl &Model::impl() const { return *impl_; }
} // namespace cdm

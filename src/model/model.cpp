// Model: nominal geometry + effects; the accessors, readings and the jig map.
// The forward kinematics is in model_position.cpp.
#include <algorithm>
#include <cmath>
#include <random>

#include "model/model_impl.h"

namespace cdm {

void Model::Impl::refresh() {
    // The order of application: by stage, built-ins in list order, user
    // effects in the order they were added.
    std::stable_sort(effects.begin(), effects.end(), [](const EffectInst &a, const EffectInst &b) {
        if (a.desc->stage != b.desc->stage) return a.desc->stage < b.desc->stage;
        const int ia = a.desc->builtin_id < 0 ? kBuiltinCount : a.desc->builtin_id;
        const int ib = b.desc->builtin_id < 0 ? kBuiltinCount : b.desc->builtin_id;
        return ia < ib;
    });
    std::vector<const EffectDesc *> d;
    for (auto &e : effects) d.push_back(e.desc.get());
    lay = build_layout(d);
}

int Model::Impl::builtin_readings(const Sample<double> &s, double out[4]) const {
    double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    for (int i = 0; i < 4; ++i) {
        gather(i, q);
        out[i] = cable_reading<double>(g, i, s, lay.cable, q);
    }
    return 0;
}

int Model::Impl::apply_user(const double p[3], double readings[4], std::string *who) const {
    if (!lay.has_user) return 0;
    for (const auto &e : effects)
        if (e.desc->stage == Stage::User && e.desc->apply_one(e.p.data(), p, readings) != 0) {
            if (who) *who = e.desc->name;
            return -1;
        }
    return 0;
}

void Model::Impl::path_frame(const Sample<double> &s, double len[4], CableFrame &f) const {
    double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    CablePoints pts;
    for (int i = 0; i < 4; ++i) {
        gather(i, q);
        len[i] = cable_path<double>(g, i, s, lay.cable, q, &pts);
        f.set(i, pts);
    }
}

void Model::Impl::transfer_of(const Sample<double> &s, const double len[4], double out[4]) const {
    double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    for (int i = 0; i < 4; ++i) {
        gather(i, q);
        out[i] = cable_transfer<double>(i, s, lay.cable, q, len[i]);
    }
}

int Model::Impl::readings_geom(const Sample<double> &s, double out[4], std::string *who) const {
    double len[4];
    CableFrame f;
    path_frame(s, len, f);
    const UserRows rows{1, s.P, &s.t_s, &f};
    // The user effects of one stage in the model's order, on v (n = 1: no
    // scratch, no allocation).
    auto stage = [&](bool on_path, double *v) {
        for (const auto &e : effects)
            if (e.desc->stage == Stage::User && e.desc->on_path == on_path &&
                call_user_effect(*e.desc, e.p.data(), rows, v) != 0) {
                if (who) *who = e.desc->name;
                return false;
            }
        return true;
    };
    if (!stage(true, len)) return -1;
    transfer_of(s, len, out);
    return stage(false, out) ? 0 : -1;
}

Model::Model(const DeviceGeometry &g) : impl_(new Impl) {
    impl_->g = g;
    impl_->refresh();
}
Model::~Model() = default;
Model::Model(const Model &o) : impl_(new Impl(*o.impl_)) {}
Model &Model::operator=(const Model &o) {
    *impl_ = *o.impl_;
    return *this;
}
const DeviceGeometry &Model::geometry() const { return impl_->g; }
size_t Model::effect_count() const { return impl_->effects.size(); }
const std::string &Model::effect_name(size_t i) const { return impl_->effects.at(i).desc->name; }
const EffectDesc &Model::effect_desc(size_t i) const { return *impl_->effects.at(i).desc; }
const std::vector<double> &Model::effect_params(size_t i) const { return impl_->effects.at(i).p; }
bool Model::has_effect(const std::string &name) const {
    for (auto &e : impl_->effects)
        if (e.desc->name == name) return true;
    return false;
}
bool Model::is_nominal() const { return impl_->effects.empty(); }

bool Model::set_effect_params(size_t i, const std::vector<double> &v, std::string &err) {
    if (i >= impl_->effects.size()) {
        err = "set_effect_params: effect index " + std::to_string(i) + " out of range (model has " +
              std::to_string(impl_->effects.size()) + " effects)";
        return false;
    }
    auto &e = impl_->effects[i];
    if (v.size() != e.p.size()) {
        err = "effect \"" + e.desc->name + "\" has " + std::to_string(e.p.size()) + " parameters, got " +
              std::to_string(v.size());
        return false;
    }
    for (size_t k = 0; k < v.size(); ++k) {
        const auto &pd = e.desc->params[k];
        if (!std::isfinite(v[k]) || v[k] < pd.lower || v[k] > pd.upper) {
            err = "parameter \"" + pd.name + "\" of effect \"" + e.desc->name + "\" must be finite and within [" +
                  std::to_string(pd.lower) + ", " + std::to_string(pd.upper) + "], got " + std::to_string(v[k]);
            return false;
        }
    }
    e.p = v;
    return true;
}

bool Model::add_effect(const std::string &name, const ParamValues &params, std::string &err) {
    auto d = find_effect(name);
    if (!d) {
        std::string known;
        for (auto &e : all_effects()) known += (known.empty() ? "" : ", ") + e->name;
        err = "unknown effect \"" + name + "\" (known: " + known + ")";
        return false;
    }
    if (has_effect(name)) {
        err = "effect \"" + name + "\" is already in the model";
        return false;
    }
    EffectInst inst{d, {}};
    for (auto &p : d->params) inst.p.push_back(p.init);
    for (const auto &kv : params) {
        const std::string &key = kv.first;
        const double value = kv.second;
        auto pit = std::find_if(d->params.begin(), d->params.end(), [&](const ParamDesc &p) { return p.name == key; });
        if (pit == d->params.end()) {
            err = "effect \"" + name + "\" has no parameter \"" + key + "\"";
            return false;
        }
        if (!std::isfinite(value)) {
            err = "parameter \"" + key + "\" of effect \"" + name + "\" must be a finite number";
            return false;
        }
        inst.p[size_t(pit - d->params.begin())] = value;
    }
    impl_->effects.push_back(std::move(inst));
    impl_->refresh();
    return true;
}

bool Model::add_effect_random(const std::string &name, uint64_t seed, std::string &err) {
    if (!add_effect(name, {}, err)) return false;
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 12345);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (auto &e : impl_->effects) {
        if (e.desc->name != name) continue;
        for (size_t k = 0; k < e.p.size(); ++k) {
            const auto &pd = e.desc->params[k];
            double mag = pd.rand_lo + (pd.rand_hi - pd.rand_lo) * u(rng);
            double sign = (pd.signed_random && u(rng) < 0.5) ? -1.0 : 1.0;
            e.p[k] = std::clamp(sign * mag, pd.lower, pd.upper);
        }
    }
    return true;
}

void Model::jig_to_device(const double ref[3], double out[3]) const {
    for (int k = 0; k < 3; ++k) out[k] = ref[k];
    jig_map<double>(impl_->whole_params(), out);
}

int Model::readings(const double p[3], double t_s, double out[4]) const {
    Sample<double> s;
    for (int k = 0; k < 3; ++k) s.P[k] = p[k];
    s.t_s = t_s;
    if (impl_->lay.has_geom) return impl_->readings_geom(s, out, nullptr);
    impl_->builtin_readings(s, out);
    return impl_->apply_user(p, out, nullptr);
}

} // namespace cdm

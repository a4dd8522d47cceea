// Model: nominal geometry + effects; readings, forward kinematics, JSON.
#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Dense>
#include <unsupported/Eigen/AutoDiff>

#include "model/model_impl.h"

namespace cdm {

void Model::Impl::refresh() {
    std::stable_sort(effects.begin(), effects.end(), [](const EffectInst &a, const EffectInst &b) {
        if (a.desc->stage != b.desc->stage) return a.desc->stage < b.desc->stage;
        int ia = a.desc->builtin_id < 0 ? 1000 : a.desc->builtin_id;
        int ib = b.desc->builtin_id < 0 ? 1000 : b.desc->builtin_id;
        return ia < ib;
    });
    idx.fill(-1);
    has_user = false;
    reading_effects = false;
    for (size_t k = 0; k < effects.size(); ++k) {
        const auto &d = *effects[k].desc;
        if (d.builtin_id >= 0) idx[d.builtin_id] = int(k);
        if (d.stage == Stage::User) has_user = true;
        if (d.stage != Stage::Jig && d.stage != Stage::Position) reading_effects = true;
    }
}

CableVars<double> Model::Impl::cable_vars(int i) const {
    CableVars<double> v{};
    if (auto a = params(E_ANCHOR))
        for (int k = 0; k < 3; ++k) v.dA[k] = a[3 * i + k];
    if (auto h = params(E_HOLDER))
        for (int k = 0; k < 3; ++k) v.dh[k] = h[3 * i + k];
    if (auto r = params(E_PULLEY)) v.r = r[0];
    if (auto s = params(E_STRETCH)) {
        v.s0 = s[0];
        v.s1 = s[1];
    }
    if (auto gn = params(E_GAIN)) v.g = gn[i];
    if (auto k2 = params(E_NONLIN)) v.k2 = k2[i];
    if (auto o = params(E_OFFSET)) v.off = o[i];
    return v;
}

void Model::Impl::builtin_readings(const double p[3], double out[4]) const {
    for (int i = 0; i < 4; ++i) out[i] = cable_reading<double>(g, i, p, cable_vars(i), pulley());
}

void Model::Impl::apply_user(const double p[3], double readings[4]) const {
    if (!has_user) return;
    for (const auto &e : effects)
        if (e.desc->stage == Stage::User) e.desc->apply(e.desc->user, e.p.data(), p, readings);
}

void Model::Impl::ellipsoid_correct(double p[3]) const {
    auto e = params(E_ELLIPSOID);
    if (!e) return;
    const double L = e[0], M = e[1], N = e[2];
    const double xc = L * (1.0 - std::sqrt(1.0 + p[1] * p[1] / (M * M) + p[2] * p[2] / (N * N)));
    p[0] -= xc;
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
bool Model::has_effect(const std::string &name) const {
    for (auto &e : impl_->effects)
        if (e.desc->name == name) return true;
    return false;
}
bool Model::is_nominal() const { return impl_->effects.empty(); }
Model::Impl &Model::impl() { return *impl_; }
const Model::Impl &Model::impl() const { return *impl_; }

bool Model::add_effect(const std::string &name, const nlohmann::json &params, std::string &err) {
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
    if (!params.is_null()) {
        if (!params.is_object()) {
            err = "parameters of effect \"" + name + "\" must be an object {name: value}";
            return false;
        }
        for (auto it = params.begin(); it != params.end(); ++it) {
            auto pit = std::find_if(d->params.begin(), d->params.end(),
                                    [&](const ParamDesc &p) { return p.name == it.key(); });
            if (pit == d->params.end()) {
                err = "effect \"" + name + "\" has no parameter \"" + it.key() + "\"";
                return false;
            }
            if (!it->is_number() || !std::isfinite(it->get<double>())) {
                err = "parameter \"" + it.key() + "\" of effect \"" + name + "\" must be a finite number";
                return false;
            }
            inst.p[pit - d->params.begin()] = it->get<double>();
        }
    }
    impl_->effects.push_back(std::move(inst));
    impl_->refresh();
    return true;
}

bool Model::add_effect(const std::string &name, const ParamValues &params, std::string &err) {
    nlohmann::json j = nlohmann::json::object();
    for (auto &kv : params) j[kv.first] = kv.second;
    return add_effect(name, j, err);
}

const EffectDesc &Model::effect_desc(size_t i) const { return *impl_->effects.at(i).desc; }

const std::vector<double> &Model::effect_params(size_t i) const { return impl_->effects.at(i).p; }

bool Model::set_effect_params(size_t i, const std::vector<double> &v, std::string &err) {
    if (i >= impl_->effects.size()) {
        err = "effect index " + std::to_string(i) + " out of range";
        return false;
    }
    auto &e = impl_->effects[i];
    if (v.size() != e.p.size()) {
        err = "effect \"" + e.desc->name + "\" takes " + std::to_string(e.p.size()) + " parameters, got " +
              std::to_string(v.size());
        return false;
    }
    for (size_t k = 0; k < v.size(); ++k) {
        const auto &pd = e.desc->params[k];
        if (!std::isfinite(v[k]) || v[k] < pd.lower || v[k] > pd.upper) {
            err = "effect \"" + e.desc->name + "\" parameter \"" + pd.name + "\" = " + std::to_string(v[k]) +
                  " is outside [" + std::to_string(pd.lower) + ", " + std::to_string(pd.upper) + "]";
            return false;
        }
    }
    e.p = v;
    return true;
}

bool Model::add_effect_random(const std::string &name, uint64_t seed, std::string &err) {
    if (!add_effect(name, nullptr, err)) return false;
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
    auto j = impl_->params(E_JIG);
    if (!j) {
        for (int k = 0; k < 3; ++k) out[k] = ref[k];
        return;
    }
    rotvec_apply<double>(j, ref, out);
    for (int k = 0; k < 3; ++k) out[k] += j[3 + k];
}

void Model::readings(const double p[3], double out[4]) const {
    impl_->builtin_readings(p, out);
    impl_->apply_user(p, out);
}

int Model::position(const double lengths[4], double p[3]) const {
    const Impl &m = *impl_;
    for (int i = 0; i < 4; ++i)
        if (!std::isfinite(lengths[i])) return -1;
    double x[3];
    const bool tri = triangulate(m.g, lengths, x);
    if (!m.reading_effects) {
        if (!tri) return -1;
        m.ellipsoid_correct(x);
        for (int k = 0; k < 3; ++k) p[k] = x[k];
        return 0;
    }
    if (!tri) {
        // Effects can push the readings past the nominal spheres' reach:
        // start from eq. (1)-(2) at mid-workspace height instead.
        const double a = m.g.a_mm, b = m.g.b_mm, mm = m.g.m_mm;
        const double R1 = lengths[0] * lengths[0], R2 = lengths[1] * lengths[1], R3 = lengths[2] * lengths[2],
                     R4 = lengths[3] * lengths[3];
        x[1] = ((R3 - R1) + (R4 - R2)) / (4.0 * (2.0 * a - mm));
        x[2] = ((R1 - R2) + (R3 - R4)) / (4.0 * (2.0 * b - mm));
        x[0] = 50.0;
    }
    // Gauss-Newton on the four readings; the 4x3 Jacobian by forward-mode AD
    // over the position (fixed-size, no allocation) for the built-ins and by
    // central differences through user effects.
    using AD = Eigen::AutoDiffScalar<Eigen::Matrix<double, 3, 1>>;
    CableVars<AD> cv[4];
    for (int i = 0; i < 4; ++i) {
        auto v = m.cable_vars(i);
        for (int k = 0; k < 3; ++k) {
            cv[i].dA[k] = v.dA[k];
            cv[i].dh[k] = v.dh[k];
        }
        cv[i].r = v.r;
        cv[i].s0 = v.s0;
        cv[i].s1 = v.s1;
        cv[i].g = v.g;
        cv[i].k2 = v.k2;
        cv[i].off = v.off;
    }
    bool ok = false;
    for (int it = 0; it < 30; ++it) {
        Eigen::Matrix<double, 4, 3> J;
        Eigen::Matrix<double, 4, 1> r;
        if (!m.has_user) {
            AD P[3];
            for (int k = 0; k < 3; ++k) P[k] = AD(x[k], 3, k);
            for (int i = 0; i < 4; ++i) {
                AD y = cable_reading<AD>(m.g, i, P, cv[i], m.pulley());
                r(i) = lengths[i] - y.value();
                J.row(i) = y.derivatives().transpose();
            }
        } else {
            double y[4];
            readings(x, y);
            for (int i = 0; i < 4; ++i) r(i) = lengths[i] - y[i];
            for (int k = 0; k < 3; ++k) {
                double xp[3] = {x[0], x[1], x[2]}, xm[3] = {x[0], x[1], x[2]};
                const double h = 1e-4;
                xp[k] += h;
                xm[k] -= h;
                double yp[4], ym[4];
                readings(xp, yp);
                readings(xm, ym);
                for (int i = 0; i < 4; ++i) J(i, k) = (yp[i] - ym[i]) / (2 * h);
            }
        }
        if (!r.allFinite() || !J.allFinite()) return -1;
        Eigen::Matrix3d H = J.transpose() * J;
        Eigen::Vector3d dx = H.ldlt().solve(J.transpose() * r);
        if (!dx.allFinite()) return -1;
        for (int k = 0; k < 3; ++k) x[k] += dx(k);
        if (dx.norm() < 1e-9) {
            ok = true;
            break;
        }
    }
    if (!ok || !(x[0] > 0) || !std::isfinite(x[0] + x[1] + x[2])) return -1;
    m.ellipsoid_correct(x);
    for (int k = 0; k < 3; ++k) p[k] = x[k];
    return 0;
}

nlohmann::json Model::to_json() const {
    nlohmann::json j;
    j["format"] = "cdm-calibration";
    j["version"] = 1;
    j["device"] = device_to_json(impl_->g);
    j["effects"] = nlohmann::json::array();
    for (auto &e : impl_->effects) {
        nlohmann::json ps = nlohmann::json::object();
        for (size_t k = 0; k < e.p.size(); ++k) ps[e.desc->params[k].name] = e.p[k];
        j["effects"].push_back({{"name", e.desc->name}, {"params", ps}});
    }
    return j;
}

bool Model::from_json(const nlohmann::json &j, const std::string &source, Model &out, std::string &err) {
    if (!j.is_object() || j.value("format", "") != "cdm-calibration") {
        err = source + ": not a cdm calibration (expected {\"format\": \"cdm-calibration\", ...})";
        return false;
    }
    if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<int>() != 1) {
        err = source + ": unsupported calibration version (this library reads version 1)";
        return false;
    }
    if (!j.contains("device")) {
        err = source + ": missing \"device\"";
        return false;
    }
    DeviceGeometry g;
    if (!parse_device_json(j["device"].dump(), source + ": device", g, err)) return false;
    Model m(g);
    if (j.contains("effects")) {
        const auto &ef = j["effects"];
        if (!ef.is_array()) {
            err = source + ": \"effects\" must be an array";
            return false;
        }
        for (size_t k = 0; k < ef.size(); ++k) {
            const auto &e = ef[k];
            if (!e.is_object() || !e.contains("name") || !e["name"].is_string()) {
                err = source + ": effects[" + std::to_string(k) + "] needs a \"name\"";
                return false;
            }
            std::string e2;
            if (!m.add_effect(e["name"].get<std::string>(), e.value("params", nlohmann::json()), e2)) {
                err = source + ": effects[" + std::to_string(k) + "]: " + e2;
                return false;
            }
        }
    }
    out = m;
    return true;
}

} // namespace cdm

// See fit_calibration.h.
#include "calib/calibration/fit_calibration.h"

#include <algorithm>
#include <cmath>
#include <future>
#include <optional>
#include <system_error>

#include "calib/fit/fit.h"
#include "model/effect.h"

namespace cdm {

using diag::V3;

namespace {

// A model of several effects contains each of its sub-models (the other
// effects at their identity), so its best fit is no worse than any of
// theirs; a joint fit from the start that ends above a sub-model fitted
// alone has stopped in a worse local minimum. Each effect alone and, with
// three or more, the model without each one are fitted from their start,
// weighed as the joint fit was (the model at its start); the joint fit is
// run again from the best of them that ends lower (the others at their
// start), and kept when it ends lower than the first. A model of one
// effect has no sub-model but the nominal, which its start is.
// An effect of the Position stage: it corrects the estimated position, so
// it is fitted in position space after the readings' fit, not with it.
bool on_position(const std::string &name) {
    const auto d = find_effect(name);
    return d && d->stage == Stage::Position;
}

bool fit_not_worse_than_nested(Model &model, const std::vector<PreparedPos> &pos, const FitOptions &f,
                               FitReport &rep, std::vector<std::string> &restarted_from) {
    const Model start = model;
    if (!fit_model(model, pos, f, rep)) return false;
    const std::vector<std::string> names = reading_effects(model);
    if (names.size() < 2) return true; // (a fit stopped short is the likeliest to be beaten)
    std::vector<std::vector<std::string>> subs;
    for (auto &n : names) subs.push_back({n});
    if (names.size() >= 3)
        for (auto &n : names) {
            subs.emplace_back();
            for (auto &o : names)
                if (o != n) subs.back().push_back(o);
        }
    FitOptions fw = f;
    fw.weigh_with = &start;
    fw.weights = nullptr;
    const double tol = 1e-6 * std::max(1.0, rep.chi2); // the fits' own convergence, not a difference
    double best = rep.chi2 - tol;
    std::optional<Model> best_sub;
    for (auto &s : subs) {
        Model sub = model_with(start, s, "");
        FitReport r;
        if (!fit_model(sub, pos, fw, r)) return false;
        if (r.converged && r.chi2 < best) best = r.chi2, best_sub = sub;
    }
    if (!best_sub) return true;
    Model again(model.geometry());
    std::string err;
    for (size_t e = 0; e < start.effect_count(); ++e) {
        const std::string &n = start.effect_name(e);
        const auto sub_effects = reading_effects(*best_sub);
        ParamValues pv;
        const bool in_sub = std::find(sub_effects.begin(), sub_effects.end(), n) != sub_effects.end();
        const Model &from = in_sub ? *best_sub : start;
        for (size_t k = 0; k < from.effect_count(); ++k)
            if (from.effect_name(k) == n)
                for (size_t q = 0; q < from.effect_desc(k).params.size(); ++q)
                    pv.push_back({from.effect_desc(k).params[q].name, from.effect_params(k)[q]});
        if (!again.add_effect(n, pv, err)) return true; // (cannot happen: the same effects)
    }
    FitReport r2;
    if (!fit_model(again, pos, fw, r2)) return false;
    if (r2.chi2 < rep.chi2) {
        model = std::move(again);
        rep = r2;
        restarted_from = reading_effects(*best_sub);
    }
    return true;
}

// The plate's holes and fixture heights in out.grid and out.fit_options.
void lay_out_jig(const Dataset &data, CalibrationFit &out) {
    out.grid = diag::make_grid(out.pos, data.heights);
    out.fit_options.hole = out.grid.hole_index; // weighed by FitOptions::hole_sigma, estimated below
    // The jig as it is (calib/evaluation/jig.h): each fixture height's own x
    // error is fitted beside the model, so that no device effect is bent to
    // follow a spacer's error.
    if (out.grid.layered && data.heights.size() >= 2) {
        out.fit_options.fixture = out.grid.height_index;
        out.fit_options.fixture_count = int(data.heights.size());
    }
}

// Each reading's own white error beyond the pots' noise of the mean (a
// pot's hysteresis, a wiper's offset per approach, a seat that tilts),
// from the cables' misclosure, which no position error moves: weighing
// the four readings as one block trusts that direction to the pots'
// noise alone, and an unseen per-reading error of 0.02 mm made a
// ripple of the noise and was recommended. Estimated from this model: a
// model error that is not smooth across the plate (a short ripple left
// unmodelled) leaks into it, and the diagnosis estimates it again on the
// model it recommends (opt.reading_noise then set; calib/diagnosis/diagnose.cpp). It
// is part of every position's noise from here on (var_mean, cov_mean):
// the fits' weights, the positions' own tests, the noise floor, and
// what the jig's tolerance is estimated beyond.
// Returns whether the model is to be fitted again with it.
bool weigh_reading_noise(const FitCalibrationOptions &opt, const Model &model, CalibrationFit &out) {
    out.reading = diag::estimate_reading_noise(out.fitted, out.grid);
    if (opt.reading_noise) {
        const diag::ReadingNoise first = out.reading;
        out.reading = *opt.reading_noise;
        out.reading.source = "re-estimated";
        out.reading.first_variance = first.variance;
        out.reading.first_se = first.se;
    }
    bool refit = false;
    if (out.reading.sigma > 0) {
        const double t2 = out.reading.sigma * out.reading.sigma;
        for (auto &p : out.pos) {
            p.var_mean.array() += t2;
            p.cov_mean.diagonal().array() += t2;
            p.reading_var = t2;
        }
        out.fitted = diag::evaluate(model, out.pos);
        refit = model.effect_count() > 0;
    }
    return refit;
}

// The seed's ellipsoid fitted in position space on top of out.model.
// The Position-stage effect `name`, fitted in closed form to what the
// physical model leaves (fit_ellipsoid, eq. 4-5), its three parameters in
// their declared order.
bool add_ellipsoid(const std::string &name, CalibrationFit &out, std::string &err) {
    Ellipsoid e2 = diag::ellipsoid_on(out.fitted, out.pos);
    const auto &ps = find_effect(name)->params;
    if (ps.size() != 3) {
        err = "effect \"" + name + "\": a Position-stage effect is the seed's ellipsoid, of 3 parameters";
        return false;
    }
    if (!out.model.add_effect(name, ParamValues{{ps[0].name, e2.L}, {ps[1].name, e2.M}, {ps[2].name, e2.N}}, err))
        return false;
    out.fitted = diag::evaluate(out.model, out.pos);
    out.report.n_free += 3;
    return true;
}

// A check's model: the calibration with a Jig-stage effect (jig_misalignment
// added at zero when it has none), every other parameter held.
bool hold_all_but_the_jig(const Model &calibration, CalibrationFit &out, std::string &err) {
    out.model = calibration;
    bool jig = false;
    for (size_t e = 0; e < out.model.effect_count(); ++e) jig = jig || out.model.effect_desc(e).stage == Stage::Jig;
    if (!jig) {
        if (!out.model.add_effect("jig_misalignment", {}, err)) return false;
        out.jig_added = true;
    }
    for (size_t e = 0; e < out.model.effect_count(); ++e)
        if (out.model.effect_desc(e).stage != Stage::Jig)
            for (size_t q = 0; q < out.model.effect_desc(e).params.size(); ++q) out.fit_options.hold.push_back({e, q});
    return true;
}

} // namespace

bool fit_calibration(const Dataset &data, const DeviceGeometry &g, const FitCalibrationOptions &opt,
                     CalibrationFit &out, std::string &err) {
    auto progress = [&](const std::string &s, double f) { return !opt.progress || opt.progress(s, f); };
    out.pos = prepare(data);
    const auto &pos = out.pos;
    if (pos.size() < 4) {
        err = data.path + ": " + std::to_string(pos.size()) + " jig positions; a fit needs at least 4";
        return false;
    }
    lay_out_jig(data, out);
    // A machined plate is within ~0.05 mm: white scatter beyond that is not
    // the jig's and must not hide an effect. Without repeated samples the
    // pots' noise is white scatter too, and there is nothing to cap against.
    const bool repeats = std::any_of(pos.begin(), pos.end(), [](const PreparedPos &p) { return p.n > 1; });
    const double jig_cap = repeats ? 0.05 : INFINITY;
    progress("nominal model", 0.0);
    // The nominal triangulation of every sample (a pass over the rows) needs
    // nothing from the fit below: with fitted_maxima it joins that pass at
    // the end; otherwise it runs on a second thread beside the fit (or
    // here, with one thread or none to be had). std::async's future waits
    // for it on every way out of this function, and get() hands on what
    // it threw.
    // With opt.nominal_pending the caller waits for it instead (and it runs
    // on beside the caller's own work): what it reads and writes is named
    // here, not captured from this function's frame.
    std::string own_err;
    std::string *const seed_err = opt.nominal_pending ? opt.nominal_err : &own_err;
    std::future<bool> own_seed;
    std::future<bool> &seed = opt.nominal_pending ? *opt.nominal_pending : own_seed;
    if (!opt.fitted_maxima) {
        auto run = [&g, &data, p = &out.pos, nominal = &out.nominal, seed_err] {
            return diag::evaluate_seed(g, data, *p, nullptr, *nominal, *seed_err);
        };
        if (opt.threads != 1) try {
                seed = std::async(std::launch::async, run);
            } catch (const std::system_error &) { // no thread to be had
            }
        if (!seed.valid() && !run()) {
            err = *seed_err;
            return false;
        }
    }

    Model &model = out.model;
    if (opt.check) {
        if (!hold_all_but_the_jig(*opt.check, out, err)) return false;
    } else {
        model = Model(g);
        for (auto &e : opt.effects) {
            if (on_position(e)) continue; // fitted in position space below
            if (!model.add_effect(e, {}, err)) return false;
        }
    }
    const bool user_jig = opt.jig_tolerance_mm >= 0;
    out.jig = V3::Constant(user_jig ? opt.jig_tolerance_mm : 0.03);
    out.fit_options.jig_sigma = out.jig;
    auto fit = [&]() {
        FitOptions f = out.fit_options;
        f.progress = [&](double fr) { return progress(opt.check ? "placing the jig" : "fitting the model", fr); };
        // A check fits the jig alone: a sub-model's fit would not hold the
        // device's parameters (FitOptions::hold names effects by index).
        if (opt.check) return fit_model(model, pos, f, out.report);
        return fit_not_worse_than_nested(model, pos, f, out.report, out.restarted_from);
    };
    if (!fit()) {
        err = out.report.message.empty() ? "fit cancelled" : out.report.message;
        return false;
    }
    out.fitted = diag::evaluate(model, pos);
    bool refit = weigh_reading_noise(opt, model, out);
    // Jig tolerance from the white part of the residual, and the part of it
    // the plate's holes share at every height; then refit with them.
    if (!user_jig) {
        V3 est = diag::estimate_nugget(out.fitted, out.grid);
        for (int a = 0; a < 3; ++a) out.jig(a) = std::min(est(a), jig_cap);
        diag::set_jig_noise(out.fit_options, out.jig, diag::estimate_hole_std(out.fitted, out.grid));
        refit = model.effect_count() > 0;
    }
    if (refit) {
        if (!fit()) {
            err = out.report.message.empty() ? "fit cancelled" : out.report.message;
            return false;
        }
        out.fitted = diag::evaluate(model, pos);
    }
    // The Position-stage effect (the seed's ellipsoid) on top of the
    // physical model, when asked for.
    const auto pe = std::find_if(opt.effects.begin(), opt.effects.end(), on_position);
    if (pe != opt.effects.end() && !add_ellipsoid(*pe, out, err)) return false;
    if (opt.fitted_maxima && !diag::sample_pass(data, pos, {&out.fitted}, {{&g, nullptr, &out.nominal}}, err))
        return false;
    if (!opt.nominal_pending && seed.valid() && !seed.get()) {
        err = *seed_err;
        return false;
    }
    return true;
}

} // namespace cdm

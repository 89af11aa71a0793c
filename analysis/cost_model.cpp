#include "analysis/cost_model.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <ctime>
#include <functional>
#include <map>
#include <numeric>
#include <set>
#include <tuple>

#include <nlohmann/json.hpp>

#include "core/base/statistics.h"
#include "core/base/error.h"
#include "core/base/number_text.h"
#include "sim/simulator.h"
#include "runner/results_reader.h"
#include "runner/results_writer.h"
#include "runner/run_experiment.h"
#include "runner/store.h"

namespace rcb {

std::string scene_category(const std::string& spec_text) {
    const nlohmann::json spec = nlohmann::json::parse(spec_text, nullptr, false);
    if (spec.is_object()) {
        if (spec.contains("kind")) return spec["kind"].get<std::string>();
        if (spec.contains("import")) return "import";
        if (spec.contains("recording")) return "recording";
    }
    return "other";
}

std::string scene_ray_mix(const std::string& spec_text) {
    const nlohmann::json spec = nlohmann::json::parse(spec_text, nullptr, false);
    if (spec.is_object() && spec.contains("ray_mix") && spec["ray_mix"].is_string())
        return spec["ray_mix"].get<std::string>();
    return "";
}

namespace {

/// A column's source: its name and how to read it from a frame.
struct Term {
    std::string name;
    std::function<double(const FrameObservation&)> value;
};

/// A table term (not a per-tier one) as a column source: its counters' sum, or 1 for a constant.
Term term_of(const CostTerm& t) {
    std::vector<double FrameObservation::*> fields;
    for (const char* symbol : t.counters) fields.push_back(find_counter(symbol).field);
    if (fields.empty()) return {t.name, [](const FrameObservation&) { return 1.0; }};
    return {t.name, [fields](const FrameObservation& f) {
                double sum = 0;
                for (const auto field : fields) sum += f.*field;
                return sum;
            }};
}

bool occurs(const std::vector<const FrameObservation*>& frames, const Term& t) {
    return std::any_of(frames.begin(), frames.end(), [&](const FrameObservation* f) { return t.value(*f) != 0; });
}

const char* target_name(Target target) { return target == Target::raycast ? "raycast" : "update"; }

/// Calibration priors by term name (the pinned values); the terms with a prior in the table but
/// none here say why.
struct Priors {
    std::map<std::string, double> value;
    std::map<std::string, std::string> why_not;
};

Priors priors_of(const StructureCalibration* calibration) {
    Priors p;
    for (const CostTerm& term : cost_terms()) {
        if (!term.prior || !term.run_prior) continue;
        const CalibratedTerm* t = calibration ? calibration->term(term.name) : nullptr;
        if (t && t->pinned)
            p.value[term.name] = t->value;
        else
            p.why_not[term.name] = t             ? t->why
                                   : calibration ? "the micro-scenes never exercise it"
                                                 : "the run has no calibration";
    }
    return p;
}

/// A column of a model: a term, restricted to one configuration when `params` is set (one cost
/// per configuration: a rebuilding and an incremental mode of one structure update differently).
struct Column {
    Term term;
    std::string params;
    std::string label;  ///< with `params`: the parameters that differ from the defaults
    std::string name() const { return params.empty() ? term.name : term.name + " {" + label + "}"; }
    double value(const FrameObservation& f) const { return params.empty() || params == f.params ? term.value(f) : 0.0; }
};

/// "margin=0,mode="rebuild"" for a registered structure's parameters, "defaults" when none differ;
/// the parameters' JSON for a structure the registry does not know.
std::string params_label(const std::string& structure, const std::string& params) {
    try {
        const nlohmann::json j = nlohmann::json::parse(params);
        std::string label = config_label(ConfigSpec{structure, j});
        label = label.size() > structure.size() ? label.substr(structure.size() + 1) : "defaults";
        return label;
    } catch (const std::exception&) {
        return params;
    }
}

/// The terms' columns, one copy per configuration of `params` (none: one shared copy).
std::vector<Column> columns_of(const std::vector<Term>& terms, const std::vector<std::string>& params = {},
                               const std::string& structure = "") {
    std::vector<Column> out;
    const std::vector<std::string> each = params.empty() ? std::vector<std::string>{""} : params;
    for (const std::string& c : each) {
        const std::string label = c.empty() ? "" : params_label(structure, c);
        for (const Term& t : terms) out.push_back({t, c, label});
    }
    return out;
}

double target_of(const FrameObservation& f, const std::string& target) {
    return target == "raycast" ? (f.rays > 0 ? f.raycast_ns / f.rays : 0.0) : f.update_ns;
}

std::vector<double> row_of(const FrameObservation& f, const std::vector<Column>& columns) {
    std::vector<double> row;
    for (const Column& c : columns) row.push_back(c.value(f));
    return row;
}

/// The problem of `columns` over `frames`; `rows` receives the index of each row's frame. Priors
/// (calibration values by term name) apply to every configuration's copy of a term.
LinearProblem build_problem(const std::vector<const FrameObservation*>& frames, const std::vector<Column>& columns,
                            const std::string& target, const std::map<std::string, double>& priors,
                            std::vector<std::size_t>* rows = nullptr) {
    LinearProblem p;
    for (const Column& c : columns) {
        p.terms.push_back(c.name());
        const auto it = priors.find(c.term.name);
        p.prior.push_back(it == priors.end() ? NAN : it->second);
    }
    std::map<std::string, int> family_of_scene, family_index;  // the k-fold's unit (linear_fit.h)
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const double y = target_of(*frames[i], target);
        if (!(y > 0)) continue;  // a zero time (timer resolution) carries no relative information
        p.x.push_back(row_of(*frames[i], columns));
        p.y.push_back(y);
        p.group.push_back(frames[i]->config_group);
        auto [it, fresh] = family_of_scene.try_emplace(frames[i]->scene, 0);
        if (fresh)
            it->second = family_index.emplace(scene_family(frames[i]->scene), int(family_index.size())).first->second;
        p.family.push_back(it->second);
        if (rows) rows->push_back(i);
    }
    return p;
}

/// The columns of `form` over `frames` (its target's), or none where the form does not apply: a
/// required term that never occurs or that some frame did not record (NaN: stored before its
/// counter existed), a split into fewer than two configurations. A term that is 0 in every frame
/// is left out unless the table keeps it, and so is one not recorded in every frame.
std::optional<std::vector<Column>> form_columns(const ModelForm& form,
                                                const std::vector<const FrameObservation*>& frames,
                                                const std::string& structure) {
    const auto recorded = [&](const Term& t) {
        return std::all_of(frames.begin(), frames.end(),
                           [&](const FrameObservation* f) { return !std::isnan(t.value(*f)); });
    };
    for (const char* name : form.required)
        if (const Term term = term_of(find_term(name)); !recorded(term) || !occurs(frames, term)) return std::nullopt;
    std::vector<Term> terms;
    for (const char* name : form.terms)
        if (Term term = term_of(find_term(name));
            recorded(term) && (find_term(name).when_absent == WhenAbsent::keep || occurs(frames, term)))
            terms.push_back(std::move(term));
    if (form.split == Split::none) return columns_of(terms);
    std::set<std::string> params;
    for (const FrameObservation* f : frames) params.insert(f->params);
    if (params.size() < 2) return std::nullopt;
    return columns_of(terms, {params.begin(), params.end()}, structure);
}

/// The table's terms of `target` that never occur in `frames` and that it names when absent.
std::vector<std::string> unused_terms(Target target, const std::vector<const FrameObservation*>& frames) {
    std::vector<std::string> out;
    for (const CostTerm& t : cost_terms())
        if (t.target == target && t.when_absent == WhenAbsent::drop_named && !occurs(frames, term_of(t)))
            out.push_back(t.name);
    return out;
}

void select(std::vector<CandidateModel>& models) {
    double best = INFINITY;
    for (const CandidateModel& m : models)
        if (std::isfinite(m.heldout_error) && m.fit.status() == "ok") best = std::min(best, m.heldout_error);
    if (!std::isfinite(best)) {  // nothing trustworthy: keep the smallest model that fitted at all, flagged
        if (!models.empty()) models.front().chosen = true;
        return;
    }
    const double tolerance = std::max(kSelectionFloor, kSelectionTolerance * best);
    // Candidates are listed from the smallest to the largest.
    for (CandidateModel& m : models)
        if (m.fit.status() == "ok" && m.heldout_error <= best + tolerance) {
            m.chosen = true;
            return;
        }
}

/// A candidate with the columns it ended with (after dropping terms the data put at 0).
struct Built {
    CandidateModel model;
    std::vector<Column> columns;
};

/// Fits `columns`; a column without a calibration prior whose coefficient comes out 0 (or, in an
/// identifiable fit, indistinguishable from 0) is dropped and the fit repeated, so that no chosen
/// coefficient sits at 0. Columns with a prior are bounded to its range and never dropped.
Built candidate(const std::string& name, const std::string& target, const std::vector<const FrameObservation*>& frames,
                std::vector<Column> columns, const Priors& priors) {
    Built b;
    b.model.name = name;
    b.model.target = target;
    for (;;) {
        b.model.problem = build_problem(frames, columns, target, priors.value);
        b.model.fit = fit_linear(b.model.problem);
        std::size_t drop = columns.size();
        for (std::size_t j = 0; j < columns.size() && columns.size() > 1; ++j) {
            if (b.model.problem.has_prior(j)) continue;
            const Coefficient& c = b.model.fit.coefficients[j];
            const bool zero = !(c.value > 0);
            const bool unsure = b.model.fit.status() == "ok" && c.spans_zero && target == "raycast";
            if (zero || unsure) {
                drop = j;
                if (zero) break;  // a zero first: it cannot be anything else
            }
        }
        if (drop == columns.size()) break;
        const Coefficient& c = b.model.fit.coefficients[drop];
        std::string why = c.name + ": ";
        const auto it = priors.why_not.find(columns[drop].term.name);
        if (it != priors.why_not.end()) why += "no calibration value (" + it->second + "); ";
        why += c.value > 0 ? "the run's frames cannot tell it from 0 (95% interval [" + fixed(c.ci_low, 3) + ", " +
                                 fixed(c.ci_high, 3) + "])"
                           : "the run's frames put it at 0";
        b.model.dropped.push_back(why);
        columns.erase(columns.begin() + std::ptrdiff_t(drop));
    }
    b.model.heldout_error = cross_validated_error(b.model.problem);
    b.columns = std::move(columns);
    return b;
}

}  // namespace

int memory_tier_of(double bytes, const std::vector<CacheLevel>& caches) {
    int tier = 0;
    for (const CacheLevel& c : caches)
        if (double(c.bytes) < bytes) ++tier;
    return std::min(tier, 3);
}

const CalibratedTerm* StructureCalibration::term(const std::string& name) const {
    for (const CalibratedTerm& t : terms)
        if (t.name == name) return &t;
    return nullptr;
}

namespace {

/// Eq. 5.4 on `points`: the table's terms with a prior that some point counts (C_HIT only where
/// `hits`), then the constants, each pinned or told why not.
StructureCalibration fit_points(const std::string& structure, std::vector<CalibrationPoint> points, bool hits) {
    StructureCalibration out;
    out.structure = structure;
    out.points = std::move(points);
    const std::vector<CalibrationPoint>& pts = out.points;
    if (pts.empty()) return out;
    std::vector<double CalibrationPoint::*> counted;  // per term; nullptr: a constant
    LinearProblem p;
    for (const bool constant : {false, true})
        for (const CostTerm& t : cost_terms()) {
            if (!t.prior || t.counters.empty() != constant || (!hits && std::string_view(t.name) == "C_HIT")) continue;
            double CalibrationPoint::*counter = constant ? nullptr : find_counter(t.counters.front()).calibrated;
            if (!constant && (!counter || !std::any_of(pts.begin(), pts.end(),
                                                       [&](const CalibrationPoint& q) { return q.*counter > 0; })))
                continue;
            p.terms.push_back(t.name);
            counted.push_back(counter);
        }
    for (std::size_t i = 0; i < pts.size(); ++i) {
        if (!(pts[i].ns_per_ray > 0)) continue;
        std::vector<double> row;
        for (double CalibrationPoint::*counter : counted) row.push_back(counter ? pts[i].*counter : 1.0);
        p.x.push_back(row);
        p.y.push_back(pts[i].ns_per_ray);
        p.group.push_back(int(i));
    }
    const LinearFit fit = fit_linear(p, 1.0);
    out.condition_number = fit.condition_number;
    for (const Coefficient& c : fit.coefficients) {
        CalibratedTerm t{c.name, c.value, c.ci_low, c.ci_high, false, ""};
        if (fit.status() != "ok")
            t.why = "the micro-scenes' fit is " + fit.status();
        else if (!(c.value > 0))
            t.why = "the micro-scenes put it at 0";
        else if (c.spans_zero)
            t.why = "its interval on the micro-scenes spans 0";
        else if (0.5 * (c.ci_high - c.ci_low) > 0.5 * c.value)
            t.why = "its interval on the micro-scenes is wider than ±50%";
        else
            t.pinned = true;
        out.terms.push_back(t);
    }
    return out;
}

}  // namespace

StructureCalibration fit_calibration(const std::string& structure, const std::vector<CalibrationPoint>& all) {
    // A structure that counts no line fetched (brute force reads in order, the peers cannot be
    // observed) would charge the large lattice's fetches to its box tests and steps: its in-cache
    // costs come from the small scenes alone.
    const bool counts_lines =
        std::any_of(all.begin(), all.end(), [](const CalibrationPoint& q) { return q.n_miss > 0; });
    std::vector<CalibrationPoint> points, without_hits;
    for (const CalibrationPoint& q : all)
        if (counts_lines || !outgrows_cache(q.scene)) {
            points.push_back(q);
            if (!prices_hits(q.scene)) without_hits.push_back(q);
        }
    // C_HIT where the micro-scenes price it: pinned, and every term pinned without it still
    // pinned. Elsewhere (a peer, whose candidates are its hits; a tree, whose tight bounds leave it
    // a few tests per ray in the cluster) the calibration goes without C_HIT and the cluster.
    StructureCalibration with = fit_points(structure, points, true);
    StructureCalibration without = fit_points(structure, without_hits, false);
    const CalibratedTerm* hit = with.term("C_HIT");
    bool priced = hit && hit->pinned;
    for (const CalibratedTerm& t : without.terms)
        if (t.pinned && !(with.term(t.name) && with.term(t.name)->pinned)) priced = false;
    return priced ? with : without;
}

std::vector<SceneSplit> scene_splits(const std::vector<const FrameObservation*>& frames) {
    // Each frame's family as an index, worked out once per scene (frames of a cell come together,
    // and names may be long).
    std::vector<SceneSplit> out;
    std::map<std::string, std::size_t> index, of_scene;
    std::vector<std::size_t> family_of(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
        auto [known, fresh] = of_scene.try_emplace(frames[i]->scene, 0);
        if (fresh) {
            const std::string family = scene_family(frames[i]->scene);
            const auto [it, added] = index.emplace(family, out.size());
            if (added) out.push_back({family, {}, {}});
            known->second = it->second;
        }
        family_of[i] = known->second;
    }
    for (std::size_t s = 0; s < out.size(); ++s)
        for (std::size_t i = 0; i < frames.size(); ++i) (family_of[i] == s ? out[s].test : out[s].train).push_back(i);
    return out;
}

const CandidateModel* StructureModels::chosen(const std::string& target) const {
    for (const CandidateModel& m : target == "raycast" ? raycast : update)
        if (m.chosen) return &m;
    return nullptr;
}

std::int64_t resolve_run(Database& db, std::int64_t run, const std::string& experiment) {
    if (run) {
        if (!run_exists(db, run)) throw InputError("--run " + std::to_string(run) + ": no such run in " + db.path());
        return run;
    }
    const std::optional<std::int64_t> latest = latest_measured_run(db, experiment);
    if (!latest)
        throw InputError(experiment.empty()
                             ? db.path() + ": the database has no measured run"
                             : "--experiment " + experiment + ": no measured run of that experiment in " + db.path());
    return *latest;
}

std::vector<FrameObservation> load_observations(Database& db, std::int64_t run, OverRepetitions how) {
    std::vector<FrameObservation> out;
    std::map<std::tuple<std::int64_t, std::int64_t>, int> groups;
    const std::map<FrameKey, double> update_median =
        how == OverRepetitions::fastest_cast ? median_update_per_frame(db, run) : std::map<FrameKey, double>{};
    // One row per frame of a cell, or with `fastest` and `fastest_cast` per frame of a (scene,
    // configuration), its fastest ray-cast and update time over the repetitions
    // (analysis/repetitions.h); `fastest_cast` puts the median update in place below.
    std::vector<std::string> columns;
    for (const FrameCounter& c : frame_counters()) columns.push_back(c.column);
    // Each scene's label, category and ray mode once, not per frame (a name or spec may be large).
    std::map<std::int64_t, std::array<std::string, 3>> scenes;
    for (const FrameCountersRow& r : read_frame_counters(db, run, how != OverRepetitions::median, columns)) {
        FrameObservation f;
        f.structure = r.structure;
        f.params = r.params;
        auto [it, fresh] = scenes.try_emplace(r.scene_id);
        if (fresh)
            if (const auto scene = read_scene_label(db, r.scene_id))
                it->second = {scene->first, scene_category(scene->second), scene_ray_mix(scene->second)};
        std::tie(f.scene, f.category, f.ray_mix) = std::tie(it->second[0], it->second[1], it->second[2]);
        const auto key = std::make_tuple(r.scene_id, r.config_id);
        f.config_group = groups.emplace(key, int(groups.size())).first->second;
        f.rays = r.rays;
        f.raycast_ns = r.raycast_ns;
        f.update_ns =
            how == OverRepetitions::fastest_cast ? update_median.at({r.scene_id, r.config_id, r.frame}) : r.update_ns;
        for (std::size_t i = 0; i < columns.size(); ++i)
            f.*(frame_counters()[i].field) = scaled_count(frame_counters()[i].scale, r.counters[i], f.rays);
        out.push_back(f);
    }
    if (out.empty()) throw InputError("run " + std::to_string(run) + " has no measured frames to fit");
    const std::vector<CacheLevel> caches = load_cache_sizes(db, run);
    for (FrameObservation& f : out) f.memory_tier = memory_tier_of(f.memory_mb * 1024.0 * 1024.0, caches);
    return out;
}

namespace {

/// Every form of `target` that applies to `frames`, fitted, from the smallest to the largest.
std::vector<Built> fit_forms(Target target, const std::vector<const FrameObservation*>& frames, const Priors& priors,
                             const std::string& structure) {
    std::vector<Built> out;
    for (const ModelForm& form : model_forms()) {
        if (form.target != target) continue;
        if (std::optional<std::vector<Column>> columns = form_columns(form, frames, structure))
            out.push_back(candidate(form.name, target_name(target), frames, std::move(*columns), priors));
    }
    return out;
}

/// Fits and selects `target`'s forms; `built` receives the candidates with their columns.
std::vector<CandidateModel> fit_target(Target target, const std::vector<const FrameObservation*>& frames,
                                       const Priors& priors, const std::string& structure, std::vector<Built>& built) {
    built = fit_forms(target, frames, priors, structure);
    std::vector<CandidateModel> models;
    for (const Built& b : built) models.push_back(b.model);
    select(models);
    return models;
}

const Built* chosen_built(const std::vector<CandidateModel>& models, const std::vector<Built>& built) {
    for (std::size_t i = 0; i < models.size(); ++i)
        if (models[i].chosen) return &built[i];
    return nullptr;
}

/// One scene predicted from the chosen models' columns fitted on every other scene's frames: per
/// configuration, the median predicted frame (update + rays × C) and ray against the measured.
SceneError predict_scene(const SceneSplit& split, const std::vector<const FrameObservation*>& fs, const Built& rc,
                         const Built& up, const Priors& priors) {
    SceneError e{split.scene, NAN, NAN};
    std::vector<const FrameObservation*> train;
    for (std::size_t i : split.train) train.push_back(fs[i]);
    const LinearProblem rp = build_problem(train, rc.columns, "raycast", priors.value);
    const LinearProblem upp = build_problem(train, up.columns, "update", {});
    if (rp.y.empty() || upp.y.empty()) return e;
    const LinearFit rf = fit_linear(rp), uf = fit_linear(upp);
    std::map<int, std::array<std::vector<double>, 4>> by_config;  // measured/predicted frame, ray
    for (std::size_t i : split.test) {
        const FrameObservation& f = *fs[i];
        const double per_ray = f.rays > 0 ? rf.predict(row_of(f, rc.columns)) : 0.0;
        auto& v = by_config[f.config_group];
        v[0].push_back(f.frame_ns());
        v[1].push_back(uf.predict(row_of(f, up.columns)) + f.rays * per_ray);
        if (f.rays > 0 && f.raycast_ns > 0) {
            v[2].push_back(f.raycast_ns / f.rays);
            v[3].push_back(per_ray);
        }
    }
    double fe = 0, re = 0;
    int fn = 0, rn = 0;
    for (const auto& [g, v] : by_config) {
        const double measured = median(v[0]);
        if (measured > 0) fe += std::abs(median(v[1]) - measured) / measured, ++fn;
        if (!v[2].empty()) {
            const double ray = median(v[2]);
            re += std::abs(median(v[3]) - ray) / ray, ++rn;
        }
    }
    if (fn) e.frame_error = fe / fn;
    if (rn) e.raycast_error = re / rn;
    return e;
}

/// A chosen model frozen: its columns and fitted coefficients as a function of a frame; NaN for a
/// frame of a configuration that a per-configuration form has no column for.
std::function<double(const FrameObservation&)> frozen(const Built& b) {
    std::vector<double> beta;
    for (const Coefficient& c : b.model.fit.coefficients) beta.push_back(c.value);
    return [columns = b.columns, beta](const FrameObservation& f) {
        double y = 0;
        bool split = false, covered = false;
        for (std::size_t j = 0; j < columns.size(); ++j) {
            split = split || !columns[j].params.empty();
            covered = covered || columns[j].params == f.params;
            y += beta[j] * columns[j].value(f);
        }
        return !split || covered ? y : NAN;
    };
}

/// Leave one scene out with the chosen models' columns (fit.loso_error): each scene's errors and
/// their means over the scenes that could be predicted.
void leave_one_scene_out(StructureModels& m, const std::vector<const FrameObservation*>& fs, const Built& rc,
                         const Built& up, const Priors& priors) {
    double frame_sum = 0, raycast_sum = 0;
    int frame_n = 0, raycast_n = 0;
    for (const SceneSplit& split : scene_splits(fs)) {
        const SceneError e = predict_scene(split, fs, rc, up, priors);
        if (!std::isnan(e.frame_error)) frame_sum += e.frame_error, ++frame_n;
        if (!std::isnan(e.raycast_error)) raycast_sum += e.raycast_error, ++raycast_n;
        m.loso.push_back(e);
    }
    if (frame_n) m.loso_error = frame_sum / frame_n;
    if (raycast_n) m.loso_raycast_error = raycast_sum / raycast_n;
}

/// The counters whose range a model records (TrainedRange), each read from a frame.
constexpr const char* kHitsPerRay = "N_TP per ray";
struct RangeCounter {
    const char* name;
    bool per_ray;  ///< read only from frames with rays
    double (*value)(const FrameObservation&);
};
const std::vector<RangeCounter>& range_counters() {
    static const std::vector<RangeCounter> counters{
        {"changes per frame", false, [](const FrameObservation& f) { return f.inserts + f.removes + f.moves; }},
        {"objects", false, [](const FrameObservation& f) { return f.objects; }},
        {"N_RB per ray", true, [](const FrameObservation& f) { return f.n_rb; }},
        {"N_T per ray", true, [](const FrameObservation& f) { return f.n_t; }},
        // Where a model prices a reported hit apart (C_HIT), the hits per ray it was fitted on: a
        // grid's price per hit, taken from rooms' walls met one or two to a cell, is no price for the
        // dozens of small triangles a ray meets in one cell of a dense mesh.
        {kHitsPerRay, true, [](const FrameObservation& f) { return f.n_tp; }},
    };
    return counters;
}

/// A cell's median of `c` over its frames (NaN: no frame to read it from).
double cell_median(const std::vector<const FrameObservation*>& cell, const RangeCounter& c) {
    std::vector<double> v;
    for (const FrameObservation* f : cell)
        if (!c.per_ray || f->rays > 0) v.push_back(c.value(*f));
    return v.empty() ? NAN : median(v);
}

std::vector<TrainedRange> trained_ranges(const std::vector<const FrameObservation*>& fs) {
    std::map<int, std::vector<const FrameObservation*>> cells;
    for (const FrameObservation* f : fs) cells[f->config_group].push_back(f);
    std::vector<TrainedRange> out;
    for (const RangeCounter& c : range_counters()) {
        TrainedRange r{c.name, INFINITY, -INFINITY};
        for (const auto& [group, cell] : cells)
            if (const double v = cell_median(cell, c); std::isfinite(v))
                r.low = std::min(r.low, v), r.high = std::max(r.high, v);
        if (r.low <= r.high) out.push_back(r);
    }
    return out;
}

/// One structure's candidates (model_forms()), chosen models and leave-one-scene-out.
StructureModels fit_structure(const std::string& structure, const std::vector<const FrameObservation*>& fs,
                              const ModelInputs& inputs) {
    StructureModels m;
    m.structure = structure;
    for (const StructureCalibration& c : inputs.calibrations)
        if (c.structure == structure) m.calibration = &c;
    const Priors priors = priors_of(m.calibration);
    m.trained = trained_ranges(fs);
    std::vector<const FrameObservation*> with_rays;
    for (const FrameObservation* f : fs)
        if (f->rays > 0) with_rays.push_back(f);
    m.unused_terms = unused_terms(Target::raycast, with_rays);
    std::vector<Built> raycast, update;
    m.raycast = fit_target(Target::raycast, with_rays, priors, structure, raycast);
    m.update = fit_target(Target::update, fs, Priors{}, structure, update);
    const Built* rc = chosen_built(m.raycast, raycast);
    const Built* up = chosen_built(m.update, update);
    if (rc && up) {
        leave_one_scene_out(m, fs, *rc, *up, priors);
        m.predict_ray = frozen(*rc);
        m.predict_update = frozen(*up);
    }
    return m;
}

}  // namespace

std::string outside_trained_range(const StructureModels& m, const std::vector<const FrameObservation*>& cell) {
    const auto text = [](double v) { return fixed(v, v >= 100 ? 0 : v >= 10 ? 1 : 2); };
    const CandidateModel* ray = m.chosen("raycast");
    const bool prices_hits =
        ray && std::find(ray->problem.terms.begin(), ray->problem.terms.end(), "C_HIT") != ray->problem.terms.end();
    std::string out;
    for (const TrainedRange& r : m.trained) {
        if (r.counter == kHitsPerRay && !prices_hits) continue;  // hits are box tests there: N_RB has them
        const auto c = std::find_if(range_counters().begin(), range_counters().end(),
                                    [&](const RangeCounter& x) { return r.counter == x.name; });
        const double v = cell_median(cell, *c);
        if (!std::isfinite(v) || (v <= r.high * kRangeMargin && v * kRangeMargin >= r.low)) continue;
        out += (out.empty() ? "" : "; ") + r.counter + " " + text(v) + " (fitted on " + text(r.low) + "–" +
               text(r.high) + ")";
    }
    return out;
}

std::vector<TermWorth> term_worth(const CandidateModel& m) {
    std::vector<TermWorth> out;
    for (std::size_t j = 0; j < m.problem.terms.size(); ++j)
        out.push_back({m.problem.terms[j],
                       m.problem.terms.size() > 1 ? cross_validated_error(m.problem.without(j)) : double(NAN)});
    return out;
}

std::vector<StructureModels> fit_cost_models(const std::vector<FrameObservation>& frames, const ModelInputs& inputs) {
    std::map<std::string, std::vector<const FrameObservation*>> by_structure;
    for (const FrameObservation& f : frames) by_structure[f.structure].push_back(&f);
    std::vector<StructureModels> out;
    for (const auto& [structure, fs] : by_structure) out.push_back(fit_structure(structure, fs, inputs));
    return out;
}

ModelInputs load_model_inputs(Database& db, std::int64_t run) {
    ModelInputs in;
    in.caches = load_cache_sizes(db, run);
    const std::vector<std::string> structures = read_calibrated_structures(db, run);
    for (const std::string& name : structures)
        in.calibrations.push_back(fit_calibration(name, load_calibration(db, run, name)));
    return in;
}

void store_fits(Database& db, std::int64_t run, const std::vector<StructureModels>& models) {
    const auto finite = [](double v) { return std::isfinite(v) ? std::optional<double>(v) : std::nullopt; };
    std::vector<StoredFit> fits;
    for (const StructureModels& s : models)
        for (const auto* list : {&s.raycast, &s.update})
            for (const CandidateModel& m : *list) {
                StoredFit f{s.structure,
                            m.target,
                            m.name,
                            nlohmann::json(m.problem.terms).dump(),
                            std::int64_t(m.fit.observations),
                            std::int64_t(m.fit.groups),
                            m.fit.r2,
                            m.fit.rmse_relative,
                            std::isfinite(m.heldout_error) ? m.heldout_error : -1.0,
                            std::isfinite(m.fit.condition_number) ? m.fit.condition_number : 1e300,
                            m.fit.status(),
                            m.chosen,
                            std::nullopt,
                            "",
                            {}};
                // Leave-one-scene-out belongs to the chosen ray-cast model (it predicts the whole frame
                // with the chosen update model); notes: the terms dropped and why.
                for (const std::string& d : m.dropped) f.notes += (f.notes.empty() ? "" : "; ") + d;
                if (m.chosen && m.target == "raycast" && std::isfinite(s.loso_error)) f.loso_error = s.loso_error;
                for (const Coefficient& c : m.fit.coefficients)
                    f.coefficients.push_back({c.name, c.value, finite(c.ci_low), finite(c.ci_high), c.spans_zero});
                fits.push_back(std::move(f));
            }
    write_fits(db, run, fits);
}

const TermShare& CostBreakdown::term(const std::string& name) const {
    for (const TermShare& t : terms)
        if (t.name == name) return t;
    throw std::logic_error("the breakdown does not show " + name);
}

namespace {

/// The ray-cast terms the Table 6.3 analog shows, in the table's order.
std::vector<const CostTerm*> breakdown_terms() {
    std::vector<const CostTerm*> out;
    for (const CostTerm& t : cost_terms())
        if (t.target == Target::raycast && t.breakdown != BreakdownShow::none) out.push_back(&t);
    return out;
}

bool counts_box_tests(const CostTerm& t) { return t.counters.size() == 1 && std::string(t.counters[0]) == "N_RB"; }

/// One (scene, configuration)'s row: the measured cost, the counts' means and, from the structure's
/// chosen ray-cast model, each term's share.
CostBreakdown breakdown_row(const std::vector<const FrameObservation*>& fs,
                            const std::vector<StructureModels>& models) {
    CostBreakdown b;
    std::vector<Term> sources;
    for (const CostTerm* t : breakdown_terms()) {
        b.terms.push_back({t->name, 0, NAN, 0});
        sources.push_back(term_of(*t));
    }
    std::vector<double> cost;
    for (const FrameObservation* f : fs) {
        cost.push_back(f->raycast_ns / f->rays);
        b.n_tp += f->n_tp, b.n_fp += f->n_rb - f->n_tp, b.n_t += f->n_t;
        for (std::size_t k = 0; k < sources.size(); ++k) b.terms[k].count += sources[k].value(*f);
    }
    const double n = double(fs.size());
    b.n_tp /= n, b.n_fp /= n, b.n_t /= n;
    for (std::size_t k = 0; k < b.terms.size(); ++k)
        // The thesis writes N_RB as N_TP + N_FP (eq. 5.4), and so does the breakdown.
        b.terms[k].count = counts_box_tests(*breakdown_terms()[k]) ? b.n_tp + b.n_fp : b.terms[k].count / n;
    b.c_total = spread_of(cost).median;
    for (const StructureModels& s : models) {
        if (s.structure != fs.front()->structure) continue;
        const CandidateModel* m = s.chosen("raycast");
        if (!m) break;
        for (TermShare& t : b.terms) {
            t.coefficient = fitted_value(m->fit.coefficients, t.name, fs.front()->category);
            t.product = t.coefficient * t.count;
        }
    }
    return b;
}

}  // namespace

std::vector<CostBreakdown> cost_breakdown(const std::vector<FrameObservation>& frames,
                                          const std::vector<StructureModels>& models) {
    std::map<std::tuple<std::string, std::string, std::string>, std::vector<const FrameObservation*>> rows;
    for (const FrameObservation& f : frames)
        if (f.rays > 0) rows[{f.scene, f.structure, f.params}].push_back(&f);
    std::vector<CostBreakdown> out;
    for (const auto& [key, fs] : rows) {
        CostBreakdown b = breakdown_row(fs, models);
        std::tie(b.scene, b.structure, b.params) = key;
        out.push_back(std::move(b));
    }
    return out;
}

BreakdownColumns breakdown_columns(const std::vector<CostBreakdown>& breakdown, const std::string& times) {
    // Which terms show: every one of kind product and value; where_priced and where_counted where
    // some row prices or counts them. Then the thesis' columns: the always-shown terms' counts (N_RB
    // as N_TP and N_FP) and coefficients.
    const std::vector<const CostTerm*> terms = breakdown_terms();
    std::vector<bool> shown(terms.size());
    for (std::size_t k = 0; k < terms.size(); ++k) {
        const BreakdownShow how = terms[k]->breakdown;
        shown[k] = how == BreakdownShow::product || how == BreakdownShow::value ||
                   std::any_of(breakdown.begin(), breakdown.end(), [&](const CostBreakdown& b) {
                       return (how == BreakdownShow::where_priced ? b.terms[k].product : b.terms[k].count) > 0;
                   });
    }
    BreakdownColumns out;
    out.header = {"C_total"};
    std::vector<std::string> counts{"N_TP", "N_FP"}, coefficients;
    for (std::size_t k = 0; k < terms.size(); ++k) {
        if (!shown[k]) continue;
        const std::string name = terms[k]->name, counter = terms[k]->counters.empty() ? "" : terms[k]->counters[0];
        if (terms[k]->breakdown == BreakdownShow::value) {
            out.header.push_back(name);
            continue;
        }
        out.header.push_back(name + times + counter);
        if (terms[k]->breakdown != BreakdownShow::product)
            out.header.push_back(counter);
        else {
            if (!counts_box_tests(*terms[k])) counts.push_back(counter);
            coefficients.push_back(name);
        }
    }
    out.header.insert(out.header.end(), counts.begin(), counts.end());
    out.header.insert(out.header.end(), coefficients.begin(), coefficients.end());
    for (const CostBreakdown& b : breakdown) {
        std::vector<std::string> row{fixed(b.c_total, 1)}, count_cells{fixed(b.n_tp, 1), fixed(b.n_fp, 1)},
            coefficient_cells;
        for (std::size_t k = 0; k < terms.size(); ++k) {
            if (!shown[k]) continue;
            const TermShare& t = b.terms[k];
            row.push_back(fixed(t.product, 1));
            if (terms[k]->breakdown == BreakdownShow::where_priced ||
                terms[k]->breakdown == BreakdownShow::where_counted)
                row.push_back(fixed(t.count, 1));
            else if (terms[k]->breakdown == BreakdownShow::product) {
                if (!counts_box_tests(*terms[k])) count_cells.push_back(fixed(t.count, 1));
                coefficient_cells.push_back(std::isfinite(t.coefficient) ? fixed(t.coefficient, 3) : "-");
            }
        }
        row.insert(row.end(), count_cells.begin(), count_cells.end());
        row.insert(row.end(), coefficient_cells.begin(), coefficient_cells.end());
        out.rows.push_back(std::move(row));
    }
    return out;
}

RunFit fit_run(Database& db, std::int64_t run, OverRepetitions how) {
    RunFit out;
    out.run = run;
    const std::vector<FrameObservation> frames = load_observations(db, run, how);
    out.frames = frames.size();
    out.inputs = std::make_shared<const ModelInputs>(load_model_inputs(db, run));
    out.models = fit_cost_models(frames, *out.inputs);
    store_fits(db, run, out.models);
    out.breakdown = cost_breakdown(frames, out.models);
    return out;
}

}  // namespace rcb

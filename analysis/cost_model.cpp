#include "analysis/cost_model.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <ctime>
#include <functional>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/base/number_text.h"
#include "core/sim/simulator.h"
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

namespace {

/// A term: its name and how to read it from a frame.
struct Term {
    std::string name;
    std::function<double(const FrameObservation&)> value;
};

const Term kNrb{"C_RB", [](const FrameObservation& f) { return f.n_rb; }};
const Term kNt{"C_T", [](const FrameObservation& f) { return f.n_t; }};
const Term kPrep{"C_PREP", [](const FrameObservation&) { return 1.0; }};
const Term kMemory{"C_MEM", [](const FrameObservation& f) { return f.memory_mb; }};
/// What a reported hit costs beyond its box test (the visit: recording it in the ray's list). The
/// thesis prices true and false positives alike (eq. 5.3); with few tests per ray, as brute force
/// on a small scene or a grid's first cell, the hits' share shows.
/// The narrow phase (thesis eq. 5.3): a test of an object's exact shape after its box was hit.
const Term kShapes{"C_RO", [](const FrameObservation& f) { return f.n_ro; }};
const Term kHits{"C_HIT", [](const FrameObservation& f) { return f.n_tp; }};
/// What a tree step costs beyond a step when its node box is hit: the children pushed and, below,
/// fetched (cache misses). Eq. 5.4 prices every step alike; a BVH's steps are hits and misses.
const Term kNodeHits{"C_TH", [](const FrameObservation& f) { return f.n_th; }};
/// What a step costs beyond a predicted one when the ray before took another path (coherence): the
/// branches the CPU guessed wrong and the nodes not in the L1 cache. N_MP is the steps a history
/// predictor missed (core/accel/outcome_predictor.h); eq. 5.4 prices coherent and incoherent rays alike.
const Term kMispredicts{"C_MP", [](const FrameObservation& f) { return f.n_mp; }};

/// The memory hierarchy: one column per cache tier the run's working sets reach beyond the smallest
/// one, named `prefix` + the tier, worth `value` of a frame where its working set has left the cache
/// of level `tier` (and every smaller one), 0 elsewhere. None when every working set sits in one tier.
std::vector<Term> tier_terms(const std::vector<const FrameObservation*>& frames, const std::string& prefix,
                             const std::function<double(const FrameObservation&)>& value) {
    std::set<int> tiers;
    for (const FrameObservation* f : frames) tiers.insert(f->memory_tier);
    std::vector<Term> out;
    if (tiers.size() < 2) return out;  // one tier only: the base costs already are its costs
    for (auto it = std::next(tiers.begin()); it != tiers.end(); ++it) {
        const int tier = *it;
        out.push_back({prefix + std::to_string(tier),
                       [=](const FrameObservation& f) { return f.memory_tier >= tier ? value(f) : 0.0; }});
    }
    return out;
}
/// Ray cast: (w_RB·N_RB + w_T·N_T) beyond each tier. The weights are the calibration's in-cache
/// costs (from small scenes), so the coefficient is the extra fraction of the in-cache cost that a
/// test and a step pay there; without a calibration value a weight is 1 (the coefficient is then in
/// ns per unit).
std::vector<Term> hierarchy_terms(const std::vector<const FrameObservation*>& frames, double w_rb, double w_t) {
    return tier_terms(frames, "slow>L", [=](const FrameObservation& f) { return w_rb * f.n_rb + w_t * f.n_t; });
}
const Term kInsert{"c_insert", [](const FrameObservation& f) { return f.inserts; }};
const Term kRemove{"c_remove", [](const FrameObservation& f) { return f.removes; }};
const Term kMove{"c_move", [](const FrameObservation& f) { return f.moves; }};
const Term kObjects{"c_object", [](const FrameObservation& f) { return f.objects; }};
const Term kFrame{"c_frame", [](const FrameObservation&) { return 1.0; }};
/// One price for any change: where a run's scenes mix inserts, removes and moves in one proportion
/// (the thesis' 1% dynamics everywhere), the per-operation costs cannot be told apart.
const Term kChange{"c_change", [](const FrameObservation& f) { return f.inserts + f.removes + f.moves; }};
/// Updates: a frame's changes beyond each tier, what a change pays beyond its in-cache cost when the
/// cells or nodes it touches are no longer cached.
std::vector<Term> update_hierarchy_terms(const std::vector<const FrameObservation*>& frames) {
    return tier_terms(frames, "c_change>L", kChange.value);
}

/// A column of a model: a term, restricted to one scene category when `category` is set.
/// With `by_params`, `category` holds a configuration's parameters instead (one cost per
/// configuration: a rebuilding and an incremental mode of one structure update differently).
struct Column {
    Term term;
    std::string category;
    bool by_params = false;
    std::string label;  ///< with `by_params`: the parameters that differ from the defaults
    std::string name() const {
        return category.empty() ? term.name
               : by_params      ? term.name + " {" + label + "}"
                                : term.name + "[" + category + "]";
    }
    double value(const FrameObservation& f) const {
        return category.empty() || category == (by_params ? f.params : f.category) ? term.value(f) : 0.0;
    }
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

std::vector<Column> columns_of(const std::vector<Term>& terms, const std::vector<std::string>& categories = {},
                               bool by_params = false, const std::string& structure = "") {
    std::vector<Column> out;
    const std::vector<std::string> cats = categories.empty() ? std::vector<std::string>{""} : categories;
    for (const std::string& c : cats) {
        const std::string label = by_params ? params_label(structure, c) : "";
        for (const Term& t : terms) out.push_back({t, c, by_params, label});
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
/// (calibration values by term name) apply to every category's copy of a term.
LinearProblem build_problem(const std::vector<const FrameObservation*>& frames, const std::vector<Column>& columns,
                            const std::string& target, const std::map<std::string, double>& priors,
                            std::vector<std::size_t>* rows = nullptr) {
    LinearProblem p;
    for (const Column& c : columns) {
        p.terms.push_back(c.name());
        const auto it = priors.find(c.term.name);
        p.prior.push_back(it == priors.end() ? NAN : it->second);
    }
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const double y = target_of(*frames[i], target);
        if (!(y > 0)) continue;  // a zero time (timer resolution) carries no relative information
        p.x.push_back(row_of(*frames[i], columns));
        p.y.push_back(y);
        p.group.push_back(frames[i]->config_group);
        if (rows) rows->push_back(i);
    }
    return p;
}

/// Drops terms that are 0 in every frame (they cannot be fitted and the structure does not have them).
std::vector<Term> present(const std::vector<const FrameObservation*>& frames, const std::vector<Term>& terms,
                          std::vector<std::string>* unused = nullptr) {
    std::vector<Term> out;
    for (const Term& t : terms) {
        const bool any =
            std::any_of(frames.begin(), frames.end(), [&](const FrameObservation* f) { return t.value(*f) != 0; });
        if (any)
            out.push_back(t);
        else if (unused && std::find(unused->begin(), unused->end(), t.name) == unused->end())
            unused->push_back(t.name);
    }
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
                std::vector<Column> columns, const std::map<std::string, double>& priors,
                const std::map<std::string, std::string>& no_prior_why) {
    Built b;
    b.model.name = name;
    b.model.target = target;
    for (;;) {
        b.model.problem = build_problem(frames, columns, target, priors);
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
        const auto it = no_prior_why.find(columns[drop].term.name);
        if (it != no_prior_why.end()) why += "no calibration value (" + it->second + "); ";
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

double median_of(std::vector<double> v) { return spread_of(std::move(v)).median; }

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

StructureCalibration fit_calibration(const std::string& structure, const std::vector<CalibrationPoint>& points) {
    StructureCalibration out;
    out.structure = structure;
    out.points = points;
    if (points.empty()) return out;
    const std::pair<const char*, double CalibrationPoint::*> counters[] = {
        {"C_RB", &CalibrationPoint::n_rb}, {"C_T", &CalibrationPoint::n_t}, {"C_MP", &CalibrationPoint::n_mp}};
    LinearProblem p;
    for (const auto& counter : counters)  // not a structured binding: clang 14 cannot capture one
        if (std::any_of(points.begin(), points.end(),
                        [&](const CalibrationPoint& q) { return q.*(counter.second) > 0; }))
            p.terms.push_back(counter.first);
    p.terms.push_back("C_PREP");
    for (std::size_t i = 0; i < points.size(); ++i) {
        if (!(points[i].ns_per_ray > 0)) continue;
        std::vector<double> row;
        for (const std::string& t : p.terms)
            row.push_back(t == "C_RB"   ? points[i].n_rb
                          : t == "C_T"  ? points[i].n_t
                          : t == "C_MP" ? points[i].n_mp
                                        : 1.0);
        p.x.push_back(row);
        p.y.push_back(points[i].ns_per_ray);
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

std::vector<SceneSplit> scene_splits(const std::vector<const FrameObservation*>& frames) {
    // Each frame's scene as an index, compared once per frame (frames of a cell come together, and
    // names may be long).
    std::vector<SceneSplit> out;
    std::map<std::string, std::size_t> index;
    std::vector<std::size_t> scene_of(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
        if (i > 0 && frames[i]->scene == frames[i - 1]->scene) {
            scene_of[i] = scene_of[i - 1];
            continue;
        }
        const auto [it, added] = index.emplace(frames[i]->scene, out.size());
        if (added) out.push_back({frames[i]->scene, {}, {}});
        scene_of[i] = it->second;
    }
    for (std::size_t s = 0; s < out.size(); ++s)
        for (std::size_t i = 0; i < frames.size(); ++i) (scene_of[i] == s ? out[s].test : out[s].train).push_back(i);
    return out;
}

const CandidateModel* StructureModels::chosen(const std::string& target) const {
    for (const CandidateModel& m : target == "raycast" ? raycast : update)
        if (m.chosen) return &m;
    return nullptr;
}

std::int64_t resolve_run(Database& db, std::int64_t run, const std::string& experiment) {
    if (run) {
        Statement s = db.prepare("SELECT id FROM run WHERE id = ?");
        s.bind(1, run);
        if (!s.step()) throw InputError("--run " + std::to_string(run) + ": no such run in " + db.path());
        return run;
    }
    Statement s = db.prepare(
        experiment.empty()
            ? "SELECT run.id FROM run WHERE EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id "
              "DESC LIMIT 1"
            : "SELECT run.id FROM run JOIN experiment ON experiment.id = run.experiment_id WHERE experiment.name = ? "
              "AND EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id DESC LIMIT 1");
    if (!experiment.empty()) s.bind(1, experiment);
    if (!s.step())
        throw InputError(experiment.empty()
                             ? db.path() + ": the database has no measured run"
                             : "--experiment " + experiment + ": no measured run of that experiment in " + db.path());
    return s.int64(0);
}

std::vector<FrameObservation> load_observations(Database& db, std::int64_t run) {
    std::vector<FrameObservation> out;
    std::map<std::tuple<std::int64_t, std::int64_t>, int> groups;
    Statement s = db.prepare(
        "SELECT config.structure, config.params, NULL, NULL, cell.scene_id, cell.config_id, frame.rays, "
        "frame.raycast_ns, frame.update_ns, frame.n_t, frame.n_rb, frame.n_tp, frame.inserts, frame.removes, "
        "frame.moves, "
        "cell.objects, frame.memory_bytes, frame.n_ro, frame.n_th, frame.n_mp FROM frame JOIN cell ON cell.id = "
        "frame.cell_id JOIN "
        "config ON "
        "config.id = "
        "cell.config_id "
        "WHERE cell.run_id IN " +
        std::string(kRunGroupSql) + " AND frame.warmup = 0 ORDER BY cell.id, frame.frame");
    s.bind_all(run, run);
    // Each scene's label and category once, not per frame (a scene's name or spec may be large).
    std::map<std::int64_t, std::pair<std::string, std::string>> scenes;
    Statement scene = db.prepare("SELECT " + std::string(kSceneLabelSql) + ", scene.spec FROM scene WHERE id = ?");
    while (s.step()) {
        FrameObservation f;
        f.structure = s.text(0);
        f.params = s.text(1);
        auto [it, fresh] = scenes.try_emplace(s.int64(4));
        if (fresh) {
            scene.reset();
            scene.bind(1, s.int64(4));
            if (scene.step()) it->second = {scene.text(0), scene_category(scene.text(1))};
        }
        f.scene = it->second.first;
        f.category = it->second.second;
        const auto key = std::make_tuple(s.int64(4), s.int64(5));
        f.config_group = groups.emplace(key, int(groups.size())).first->second;
        f.rays = s.real(6);
        f.raycast_ns = s.real(7);
        f.update_ns = s.real(8);
        if (f.rays > 0) f.n_t = s.real(9) / f.rays, f.n_rb = s.real(10) / f.rays, f.n_tp = s.real(11) / f.rays;
        f.inserts = s.real(12);
        f.removes = s.real(13);
        f.moves = s.real(14);
        f.objects = s.real(15);
        f.memory_mb = s.real(16) / (1024.0 * 1024.0);
        if (f.rays > 0) f.n_ro = s.real(17) / f.rays, f.n_th = s.real(18) / f.rays, f.n_mp = s.real(19) / f.rays;
        out.push_back(f);
    }
    if (out.empty()) throw InputError("run " + std::to_string(run) + " has no measured frames to fit");
    const std::vector<CacheLevel> caches = load_cache_sizes(db, run);
    for (FrameObservation& f : out) f.memory_tier = memory_tier_of(f.memory_mb * 1024.0 * 1024.0, caches);
    return out;
}

std::vector<StructureModels> fit_cost_models(const std::vector<FrameObservation>& frames, const ModelInputs& inputs) {
    std::map<std::string, std::vector<const FrameObservation*>> by_structure;
    for (const FrameObservation& f : frames) by_structure[f.structure].push_back(&f);
    std::vector<StructureModels> out;
    for (const auto& [structure, fs] : by_structure) {
        StructureModels m;
        m.structure = structure;
        for (const StructureCalibration& c : inputs.calibrations)
            if (c.structure == structure) m.calibration = &c;
        // Priors: the pinned calibration values; the others say why they are missing.
        std::map<std::string, double> priors;
        std::map<std::string, std::string> no_prior_why;
        for (const char* name : {"C_RB", "C_T", "C_MP", "C_PREP"}) {
            const CalibratedTerm* t = m.calibration ? m.calibration->term(name) : nullptr;
            if (t && t->pinned)
                priors[name] = t->value;
            else
                no_prior_why[name] = t               ? t->why
                                     : m.calibration ? "the micro-scenes never exercise it"
                                                     : "the run has no calibration";
        }
        std::vector<const FrameObservation*> with_rays;
        for (const FrameObservation* f : fs)
            if (f->rays > 0) with_rays.push_back(f);
        std::set<std::string> category_set;
        for (const FrameObservation* f : with_rays) category_set.insert(f->category);
        const std::vector<std::string> categories(category_set.begin(), category_set.end());

        // Ray cast: from the smallest model to the largest.
        // The narrow phase's shape tests, where the structure ran any, are a cost of their own in
        // every candidate (a triangle's or a capsule's test is not a slab test; thesis eq. 5.3): a
        // model without them would charge them to the box tests. Like any term without a prior,
        // C_RO leaves a candidate when the frames cannot tell it from 0.
        std::vector<Term> core = present(with_rays, {kNrb, kNt}, &m.unused_terms);
        const bool shapes = !present(with_rays, {kShapes}, nullptr).empty();
        if (shapes) core.push_back(kShapes);
        std::vector<Term> full = core;
        full.push_back(kPrep);
        std::vector<Built> raycast;
        raycast.push_back(candidate("no-prep", "raycast", with_rays, columns_of(core), priors, no_prior_why));
        raycast.push_back(candidate("eq5.4", "raycast", with_rays, columns_of(full), priors, no_prior_why));
        // Steps the ray before did not prepare (coherence): where the traversal counted any.
        const bool coherence = !present(with_rays, {kMispredicts}, nullptr).empty();
        if (coherence) {
            std::vector<Term> with_coherence = full;
            with_coherence.push_back(kMispredicts);
            raycast.push_back(
                candidate("with-coherence", "raycast", with_rays, columns_of(with_coherence), priors, no_prior_why));
        }
        // Tree steps that enter a node (children pushed) against those that stop at its box.
        if (!present(with_rays, {kNodeHits}, nullptr).empty()) {
            std::vector<Term> with_node_hits = full;
            with_node_hits.push_back(kNodeHits);
            raycast.push_back(
                candidate("with-node-hits", "raycast", with_rays, columns_of(with_node_hits), priors, no_prior_why));
        }
        const std::vector<Term> hit_terms = present(with_rays, {kHits}, nullptr);
        if (!hit_terms.empty()) {
            std::vector<Term> with_hits = full;
            with_hits.push_back(kHits);
            raycast.push_back(
                candidate("with-hits", "raycast", with_rays, columns_of(with_hits), priors, no_prior_why));
        }
        std::vector<Term> with_memory = full;
        with_memory.push_back(kMemory);
        raycast.push_back(
            candidate("with-memory", "raycast", with_rays, columns_of(with_memory), priors, no_prior_why));
        // Per-test and per-step costs beyond each cache level the working set leaves.
        const auto has = [&](const char* name) {
            return std::any_of(core.begin(), core.end(), [&](const Term& t) { return t.name == name; });
        };
        const double w_rb = !has("C_RB") ? 0.0 : priors.count("C_RB") ? priors.at("C_RB") : 1.0;
        const double w_t = !has("C_T") ? 0.0 : priors.count("C_T") ? priors.at("C_T") : 1.0;
        const std::vector<Term> beyond = hierarchy_terms(with_rays, w_rb, w_t);
        if (!beyond.empty()) {
            std::vector<Term> hierarchy = full;
            hierarchy.insert(hierarchy.end(), beyond.begin(), beyond.end());
            raycast.push_back(
                candidate("memory-hierarchy", "raycast", with_rays, columns_of(hierarchy), priors, no_prior_why));
        }
        // Both: steps the ray before did not prepare, and steps and tests beyond the caches.
        if (coherence && !beyond.empty()) {
            std::vector<Term> both = full;
            both.push_back(kMispredicts);
            both.insert(both.end(), beyond.begin(), beyond.end());
            raycast.push_back(
                candidate("coherence-hierarchy", "raycast", with_rays, columns_of(both), priors, no_prior_why));
        }
        if (categories.size() > 1)
            raycast.push_back(
                candidate("per-category", "raycast", with_rays, columns_of(full, categories), priors, no_prior_why));
        for (Built& b : raycast) m.raycast.push_back(b.model);
        select(m.raycast);

        // Update: per-operation costs, then a per-object (rebuild) cost.
        std::vector<std::string> unused_update;
        const std::vector<Term> ops = present(fs, {kInsert, kRemove, kMove}, &unused_update);
        std::vector<Term> ops_frame = ops;
        ops_frame.push_back(kFrame);
        std::vector<Term> rebuild = ops_frame;
        rebuild.push_back(kObjects);
        std::vector<Built> update;
        const std::vector<Term> change_frame = {kChange, kFrame};
        std::vector<Term> change_rebuild = change_frame;
        change_rebuild.push_back(kObjects);
        if (!ops.empty()) update.push_back(candidate("per-change", "update", fs, columns_of(change_frame), {}, {}));
        update.push_back(candidate("per-operation", "update", fs, columns_of(ops_frame), {}, {}));
        update.push_back(candidate("with-rebuild", "update", fs, columns_of(rebuild), {}, {}));
        // Changes that touch a working set beyond the caches cost more (a 40 000-object grid's
        // cells, not a 2 000-object one's).
        const std::vector<Term> change_tiers = update_hierarchy_terms(fs);
        if (!change_tiers.empty() && !ops.empty()) {
            std::vector<Term> hierarchy = ops_frame;
            hierarchy.insert(hierarchy.end(), change_tiers.begin(), change_tiers.end());
            update.push_back(candidate("update-hierarchy", "update", fs, columns_of(hierarchy), {}, {}));
        }
        std::set<std::string> param_set;
        for (const FrameObservation* f : fs) param_set.insert(f->params);
        if (param_set.size() > 1) {  // each configuration its own update costs (e.g. incremental vs rebuild)
            if (!ops.empty())
                update.push_back(candidate(
                    "per-configuration-change", "update", fs,
                    columns_of(change_rebuild, {param_set.begin(), param_set.end()}, true, structure), {}, {}));
            update.push_back(candidate("per-configuration", "update", fs,
                                       columns_of(rebuild, {param_set.begin(), param_set.end()}, true, structure), {},
                                       {}));
        }
        for (Built& b : update) m.update.push_back(b.model);
        select(m.update);

        // Leave one scene out: the chosen models' columns fitted on every other scene, the scene's
        // frames predicted from their counters.
        const Built* rc = nullptr;
        const Built* up = nullptr;
        for (std::size_t i = 0; i < m.raycast.size(); ++i)
            if (m.raycast[i].chosen) rc = &raycast[i];
        for (std::size_t i = 0; i < m.update.size(); ++i)
            if (m.update[i].chosen) up = &update[i];
        if (rc && up) {
            double frame_sum = 0, raycast_sum = 0;
            int frame_n = 0, raycast_n = 0;
            for (const SceneSplit& split : scene_splits(fs)) {
                SceneError e{split.scene, NAN, NAN};
                std::vector<const FrameObservation*> train;
                for (std::size_t i : split.train) train.push_back(fs[i]);
                const LinearProblem rp = build_problem(train, rc->columns, "raycast", priors);
                const LinearProblem upp = build_problem(train, up->columns, "update", {});
                if (!rp.y.empty() && !upp.y.empty()) {
                    const LinearFit rf = fit_linear(rp), uf = fit_linear(upp);
                    std::map<int, std::array<std::vector<double>, 4>> by_config;  // measured/predicted frame, ray
                    for (std::size_t i : split.test) {
                        const FrameObservation& f = *fs[i];
                        const double per_ray = f.rays > 0 ? rf.predict(row_of(f, rc->columns)) : 0.0;
                        auto& v = by_config[f.config_group];
                        v[0].push_back(f.frame_ns());
                        v[1].push_back(uf.predict(row_of(f, up->columns)) + f.rays * per_ray);
                        if (f.rays > 0 && f.raycast_ns > 0) {
                            v[2].push_back(f.raycast_ns / f.rays);
                            v[3].push_back(per_ray);
                        }
                    }
                    double fe = 0, re = 0;
                    int fn = 0, rn = 0;
                    for (const auto& [g, v] : by_config) {
                        const double measured = median_of(v[0]);
                        if (measured > 0) fe += std::abs(median_of(v[1]) - measured) / measured, ++fn;
                        if (!v[2].empty()) {
                            const double ray = median_of(v[2]);
                            re += std::abs(median_of(v[3]) - ray) / ray, ++rn;
                        }
                    }
                    if (fn) e.frame_error = fe / fn, frame_sum += e.frame_error, ++frame_n;
                    if (rn) e.raycast_error = re / rn, raycast_sum += e.raycast_error, ++raycast_n;
                }
                m.loso.push_back(e);
            }
            if (frame_n) m.loso_error = frame_sum / frame_n;
            if (raycast_n) m.loso_raycast_error = raycast_sum / raycast_n;
        }
        out.push_back(std::move(m));
    }
    return out;
}

ModelInputs load_model_inputs(Database& db, std::int64_t run) {
    ModelInputs in;
    in.caches = load_cache_sizes(db, run);
    Statement s = db.prepare("SELECT DISTINCT structure FROM calibration WHERE run_id = ? ORDER BY structure");
    s.bind(1, run);
    std::vector<std::string> structures;
    while (s.step()) structures.push_back(s.text(0));
    for (const std::string& name : structures)
        in.calibrations.push_back(fit_calibration(name, load_calibration(db, run, name)));
    return in;
}

void store_fits(Database& db, std::int64_t run, const std::vector<StructureModels>& models) {
    Transaction t(db);
    db.prepare("DELETE FROM fit WHERE run_id = ?").bind(1, run).run();
    for (const StructureModels& s : models)
        for (const auto* list : {&s.raycast, &s.update})
            for (const CandidateModel& m : *list) {
                db.prepare(
                      "INSERT INTO fit(run_id, created_at, structure, target, model, terms, observations, "
                      "configurations, r2, "
                      "rmse_relative, heldout_error, condition_number, status, chosen) VALUES "
                      "(?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
                    .bind_all(run, utc_now(), s.structure, m.target, m.name, nlohmann::json(m.problem.terms).dump(),
                              std::int64_t(m.fit.observations), std::int64_t(m.fit.groups), m.fit.r2,
                              m.fit.rmse_relative, std::isfinite(m.heldout_error) ? m.heldout_error : -1.0,
                              std::isfinite(m.fit.condition_number) ? m.fit.condition_number : 1e300, m.fit.status(),
                              std::int64_t(m.chosen))
                    .run();
                const std::int64_t fit = db.last_insert_id();
                // Leave-one-scene-out belongs to the chosen ray-cast model (it predicts the whole frame
                // with the chosen update model); notes: the terms dropped and why.
                std::string notes;
                for (const std::string& d : m.dropped) notes += (notes.empty() ? "" : "; ") + d;
                const bool loso = m.chosen && m.target == "raycast" && std::isfinite(s.loso_error);
                db.prepare("UPDATE fit SET loso_error = ?, notes = ? WHERE id = ?")
                    .bind(1, loso ? std::optional<double>(s.loso_error) : std::nullopt)
                    .bind(2, notes)
                    .bind(3, fit)
                    .run();
                for (const Coefficient& c : m.fit.coefficients) {
                    Statement ins = db.prepare(
                        "INSERT INTO fit_coefficient(fit_id, name, value, ci_low, ci_high, spans_zero) VALUES "
                        "(?,?,?,?,?,?)");
                    ins.bind_all(fit, c.name, c.value);
                    ins.bind(4, std::isfinite(c.ci_low) ? std::optional<double>(c.ci_low) : std::nullopt);
                    ins.bind(5, std::isfinite(c.ci_high) ? std::optional<double>(c.ci_high) : std::nullopt);
                    ins.bind(6, std::int64_t(c.spans_zero));
                    ins.run();
                }
            }
    t.commit();
}

std::vector<CostBreakdown> cost_breakdown(const std::vector<FrameObservation>& frames,
                                          const std::vector<StructureModels>& models) {
    std::map<std::tuple<std::string, std::string, std::string>, std::vector<const FrameObservation*>> rows;
    for (const FrameObservation& f : frames)
        if (f.rays > 0) rows[{f.scene, f.structure, f.params}].push_back(&f);
    std::vector<CostBreakdown> out;
    for (const auto& [key, fs] : rows) {
        CostBreakdown b;
        std::tie(b.scene, b.structure, b.params) = key;
        std::vector<double> cost;
        for (const FrameObservation* f : fs) {
            cost.push_back(f->raycast_ns / f->rays);
            b.n_tp += f->n_tp, b.n_fp += f->n_rb - f->n_tp, b.n_t += f->n_t, b.n_ro += f->n_ro, b.n_mp += f->n_mp;
        }
        const double n = double(fs.size());
        b.n_tp /= n, b.n_fp /= n, b.n_t /= n, b.n_ro /= n, b.n_mp /= n;
        b.c_total = spread_of(cost).median;
        const std::string category = fs.front()->category;
        for (const StructureModels& s : models) {
            if (s.structure != b.structure) continue;
            const CandidateModel* m = s.chosen("raycast");
            if (!m) break;
            auto coefficient = [&](const std::string& name) {
                for (const Coefficient& c : m->fit.coefficients)
                    if (c.name == name || c.name == name + "[" + category + "]") return c.value;
                return 0.0;
            };
            b.c_rb = coefficient("C_RB");
            b.c_t = coefficient("C_T");
            b.prep = coefficient("C_PREP");
            b.rb_term = b.c_rb * (b.n_tp + b.n_fp);
            b.t_term = b.c_t * b.n_t;
            b.ro_term = coefficient("C_RO") * b.n_ro;
            b.mp_term = coefficient("C_MP") * b.n_mp;
        }
        out.push_back(b);
    }
    return out;
}

std::optional<RaycastCoefficients> stored_raycast_coefficients(Database& db, std::int64_t run,
                                                               const std::string& structure,
                                                               const std::string& category) {
    Statement s = db.prepare(
        "SELECT fit.model, fit_coefficient.name, fit_coefficient.value FROM fit JOIN fit_coefficient ON "
        "fit_coefficient.fit_id = fit.id "
        "WHERE fit.run_id = ? AND fit.structure = ? AND fit.target = 'raycast' AND fit.chosen = 1");
    s.bind_all(run, structure);
    std::optional<RaycastCoefficients> out;
    while (s.step()) {
        if (!out) out = RaycastCoefficients{0, 0, 0, s.text(0)};
        std::string name = s.text(1);
        const auto bracket = name.find('[');
        if (bracket != std::string::npos) {  // per-category: only this scene's category
            if (name.substr(bracket) != "[" + category + "]") continue;
            name = name.substr(0, bracket);
        }
        if (name == "C_RB")
            out->c_rb = s.real(2);
        else if (name == "C_T")
            out->c_t = s.real(2);
        else if (name == "C_PREP")
            out->c_prep = s.real(2);
    }
    return out;
}

BreakdownColumns breakdown_columns(const std::vector<CostBreakdown>& breakdown, const std::string& times) {
    const bool shapes =
        std::any_of(breakdown.begin(), breakdown.end(), [](const CostBreakdown& b) { return b.n_ro > 0; });
    const bool coherence =
        std::any_of(breakdown.begin(), breakdown.end(), [](const CostBreakdown& b) { return b.mp_term > 0; });
    BreakdownColumns out;
    out.header = {"C_total", "C_RB" + times + "N_RB", "C_T" + times + "N_T"};
    if (coherence) out.header.insert(out.header.end(), {"C_MP" + times + "N_MP", "N_MP"});
    if (shapes) out.header.insert(out.header.end(), {"C_RO" + times + "N_RO", "N_RO"});
    out.header.insert(out.header.end(), {"C_PREP", "N_TP", "N_FP", "N_T", "C_RB", "C_T"});
    for (const CostBreakdown& b : breakdown) {
        std::vector<std::string> row{fixed(b.c_total, 1), fixed(b.rb_term, 1), fixed(b.t_term, 1)};
        if (coherence) row.insert(row.end(), {fixed(b.mp_term, 1), fixed(b.n_mp, 1)});
        if (shapes) row.insert(row.end(), {fixed(b.ro_term, 1), fixed(b.n_ro, 1)});
        row.insert(row.end(),
                   {fixed(b.prep, 1), fixed(b.n_tp, 1), fixed(b.n_fp, 1), fixed(b.n_t, 1),
                    std::isfinite(b.c_rb) ? fixed(b.c_rb, 3) : "-", std::isfinite(b.c_t) ? fixed(b.c_t, 3) : "-"});
        out.rows.push_back(std::move(row));
    }
    return out;
}

RunFit fit_run(Database& db, std::int64_t run) {
    RunFit out;
    out.run = run;
    const std::vector<FrameObservation> frames = load_observations(db, run);
    out.frames = frames.size();
    out.inputs = std::make_shared<const ModelInputs>(load_model_inputs(db, run));
    out.models = fit_cost_models(frames, *out.inputs);
    store_fits(db, run, out.models);
    out.breakdown = cost_breakdown(frames, out.models);
    return out;
}

}  // namespace rcb

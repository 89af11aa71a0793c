#include "analysis/model_terms.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "analysis/linear_fit.h"
#include "core/base/error.h"
#include "accel/model/counter_fields.h"
#include "core/scene/generate/generators.h"
#include "sim/simulator.h"
#include "runner/calibration.h"

namespace rcb {

std::string scene_family(const std::string& scene) {
    static const std::vector<std::string> modes = ray_mode_names();
    std::vector<std::string> kept;
    std::size_t start = 0;
    for (;;) {
        const std::size_t dash = scene.find('-', start);
        const std::string segment = scene.substr(start, dash == std::string::npos ? std::string::npos : dash - start);
        const bool last = dash == std::string::npos;
        const bool mode = std::find(modes.begin(), modes.end(), segment) != modes.end();
        const bool seed = last && segment.size() > 1 && segment[0] == 's' &&
                          segment.find_first_not_of("0123456789", 1) == std::string::npos;
        const bool representation =
            last && (segment == "brushes" || segment == "triangles" || segment == "instances" || segment == "obbs");
        if (!mode && !seed && !representation) kept.push_back(segment);
        if (last) break;
        start = dash + 1;
    }
    if (kept.empty()) return scene;
    std::string family = kept.front();
    for (std::size_t i = 1; i < kept.size(); ++i) family += "-" + kept[i];
    return family;
}

const std::vector<FrameCounter>& frame_counters() {
    using F = FrameObservation;
    using C = CalibrationPoint;
    static const std::vector<FrameCounter> counters = [] {
        std::vector<FrameCounter> table{
            {"N_RB", "frame.n_rb", "n_rb", CounterScale::per_ray, &F::n_rb, nullptr, &C::n_rb},
            {"N_T", "frame.n_t", "n_t", CounterScale::per_ray, &F::n_t, nullptr, &C::n_t},
            {"N_TP", "frame.n_tp", "n_tp", CounterScale::per_ray, &F::n_tp, nullptr, &C::n_tp},
            {"N_RO", "frame.n_ro", "n_ro", CounterScale::per_ray, &F::n_ro, nullptr, nullptr},
            {"N_TH", "frame.n_th", "n_th", CounterScale::per_ray, &F::n_th, nullptr, nullptr},
            {"N_MP", "frame.n_mp", "n_mp", CounterScale::per_ray, &F::n_mp, nullptr, &C::n_mp},
            {"N_MISS", "frame.n_miss", "n_miss", CounterScale::per_ray, &F::n_miss, nullptr, &C::n_miss},
            {"N_INS", "frame.inserts", "inserts", CounterScale::as_is, &F::inserts,
             [](const FrameResult& r) { return double(r.inserts); }, nullptr},
            {"N_REM", "frame.removes", "removes", CounterScale::as_is, &F::removes,
             [](const FrameResult& r) { return double(r.removes); }, nullptr},
            {"N_MOV", "frame.moves", "moves", CounterScale::as_is, &F::moves,
             [](const FrameResult& r) { return double(r.moves); }, nullptr},
            {"N_UW", "frame.writes", "writes", CounterScale::as_is, &F::writes,
             [](const FrameResult& r) { return double(r.writes); }, nullptr},
            {"N_UP", "frame.update_work", "update_work", CounterScale::as_is, &F::update_work,
             [](const FrameResult& r) { return double(r.update_work); }, nullptr},
            {"N_OBJ", "cell.objects", "objects", CounterScale::as_is, &F::objects, nullptr, nullptr},
            {"MB", "frame.memory_bytes", "memory_bytes", CounterScale::mebibytes, &F::memory_mb,
             [](const FrameResult& r) { return double(r.memory_bytes); }, nullptr},
        };
        for (FrameCounter& c : table)
            if (const CounterField* f = counter_field(c.alias)) c.counted = f->member;
        return table;
    }();
    return counters;
}

const std::vector<CostTerm>& cost_terms() {
    using enum Target;
    using enum WhenAbsent;
    using enum BreakdownShow;
    static const std::vector<CostTerm> terms{
        // Eq. 5.4. The thesis writes N_RB as N_TP + N_FP; the Table 6.3 analog does too.
        {.name = "C_RB",
         .target = raycast,
         .counters = {"N_RB"},
         .unit = "ns per box test",
         .when_absent = drop_named,
         .prior = true,
         .in_tuning = true,
         .traversal = true,
         .breakdown = product},
        {.name = "C_T",
         .target = raycast,
         .counters = {"N_T"},
         .unit = "ns per traversal step",
         .when_absent = drop_named,
         .prior = true,
         .in_tuning = true,
         .traversal = true,
         .breakdown = product},
        // Coherence: what a step costs beyond a predicted one when the ray before took another path
        // (branches guessed wrong, nodes not in L1); N_MP from accel/model/outcome_predictor.h.
        {.name = "C_MP",
         .target = raycast,
         .counters = {"N_MP"},
         .unit = "ns per unpredicted step",
         .prior = true,
         .in_tuning = true,
         .optional_in_json = true,
         .traversal = true,
         .breakdown = where_priced},
        // Footprint: what a line costs that the batch fetched from beyond the core's private cache
        // (N_MISS from accel/model/cache_model.h). Rays spread over a scene pay it; rays aimed at one
        // region find their cells and nodes cached, whatever N_RB and N_T they count. The large
        // lattice of the calibration pins it.
        {.name = "C_MISS",
         .target = raycast,
         .counters = {"N_MISS"},
         .unit = "ns per line fetched",
         .prior = true,
         .in_tuning = true,
         .optional_in_json = true,
         .traversal = true,
         .breakdown = where_priced},
        // The narrow phase (eq. 5.3): a test of an object's exact shape after its box was hit.
        {.name = "C_RO",
         .target = raycast,
         .counters = {"N_RO"},
         .unit = "ns per shape test",
         .in_tuning = true,
         .breakdown = where_counted},
        {.name = "C_PREP",
         .target = raycast,
         .counters = {},
         .unit = "ns per ray",
         .when_absent = keep,
         .prior = true,
         .in_tuning = true,
         .breakdown = value},
        // What a reported hit costs beyond its box test: its entry in the ray's list and, in a grid,
        // the check against the objects met in earlier cells. Eq. 5.3 prices true and false
        // positives alike; the calibration's stack and cluster pin it apart from C_RB where they can
        // (fit_calibration), so that C_RB is a box test's cost. Rays through a map's rooms pay far
        // more per hit than the micro-scenes' one-cell stack does (docs/model.md, "Hits"), so a
        // run's fit takes it from its frames alone.
        {.name = "C_HIT",
         .target = raycast,
         .counters = {"N_TP"},
         .unit = "ns per reported hit",
         .prior = true,
         .run_prior = false,
         .in_tuning = true,
         .optional_in_json = true,
         .breakdown = where_priced},
        {.name = "c_object", .target = update, .counters = {"N_OBJ"}, .unit = "ns per object", .when_absent = keep},
        // The cells, entries and nodes an update wrote (Structure::writes): an incremental tree
        // that rebuilds when its height or SAH cost outgrew its guard rewrites the whole tree in
        // that frame, at a price per change of ten times its usual one (docs/model.md).
        {.name = "c_write", .target = update, .counters = {"N_UW"}, .unit = "ns per write"},
        {.name = "c_frame", .target = update, .counters = {}, .unit = "ns per frame", .when_absent = keep},
        // What the update did that its writes do not show (Structure::update_work): a linear BVH's
        // keys placed by a full radix sort, which a rebuild that merges from the last order skips
        // (same writes, about half the time), and a wide BVH's blocks read by the descents of its
        // reinsertions (docs/model.md, "Footprint of an update").
        {.name = "c_work", .target = update, .counters = {"N_UP"}, .unit = "ns per unit of update work"},
        // One price for any change (eq. 5.5 prices inserts, removes and moves apart; where a run
        // mixes them in one proportion, as the thesis' 1% dynamics everywhere, their own costs
        // cannot be told apart, and no scene set measured so far told them apart: docs/model.md).
        {.name = "c_change",
         .target = update,
         .counters = {"N_INS", "N_REM", "N_MOV"},
         .unit = "ns per change",
         .when_absent = keep},
    };
    return terms;
}

const std::vector<ModelForm>& model_forms() {
    using enum Target;
    static const std::vector<ModelForm> forms{
        // Ray cast: the thesis' eq. 5.4, and the two forms that earned their place under grouped
        // nested validation (docs/model.md, "Which forms are kept"). C_RO is in every form where
        // shapes were tested: a form without it would charge the shape tests to the box tests
        // (eq. 5.3).
        {"eq5.4", raycast, {"C_RB", "C_T", "C_RO", "C_PREP"}},
        {"with-coherence", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP"}, {"C_MP"}},
        {"coherence-misses", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP", "C_MISS", "C_HIT"}, {"C_MP", "C_MISS"}},
        // Update: one price per change; one per change, object and unit of the update's work where
        // a structure counts work its writes do not show (a tree that rebuilds every frame pays per
        // object, a tree that reinserts per block its descents read); and each configuration its
        // own with a per-object and a per-write cost (an incremental and a rebuilding mode of one
        // structure update differently, and an incremental tree's rebuilds write what its changes
        // alone do not say).
        {"per-change", update, {"c_change", "c_frame"}, {"c_change"}},
        {"per-change-work", update, {"c_change", "c_frame", "c_object", "c_work"}, {"c_change", "c_work"}},
        {"per-configuration-change",
         update,
         {"c_change", "c_frame", "c_object", "c_write"},
         {"c_change"},
         Split::by_params},
    };
    return forms;
}

const CostTerm& find_term(std::string_view name) {
    for (const CostTerm& t : cost_terms())
        if (t.name == name) return t;
    throw std::logic_error("no cost-model term " + std::string(name));
}

const FrameCounter& find_counter(std::string_view symbol) {
    for (const FrameCounter& c : frame_counters())
        if (c.symbol == symbol) return c;
    throw std::logic_error("no frame counter " + std::string(symbol));
}

double term_value(const CostTerm& term, const FrameObservation& f) {
    if (term.counters.empty()) return 1.0;
    double sum = 0;
    for (const char* symbol : term.counters) sum += f.*(find_counter(symbol).field);
    return sum;
}

double scaled_count(CounterScale scale, double raw, double rays) {
    switch (scale) {
        case CounterScale::per_ray:
            return rays > 0 ? raw / rays : 0.0;
        case CounterScale::mebibytes:
            return raw / (1024.0 * 1024.0);
        case CounterScale::as_is:
            break;
    }
    return raw;
}

FrameObservation observation_of(const FrameResult& frame, double objects) {
    FrameObservation o;
    o.rays = frame.rays;
    o.raycast_ns = double(frame.raycast_ns);
    o.update_ns = double(frame.update_ns);
    for (const FrameCounter& c : frame_counters()) {
        const double raw = c.counted ? double(frame.counters.*(c.counted)) : c.simulated ? c.simulated(frame) : objects;
        o.*(c.field) = scaled_count(c.scale, raw, double(frame.rays));
    }
    return o;
}

const std::vector<const CostTerm*>& tuning_terms() {
    static const std::vector<const CostTerm*> terms = [] {
        std::vector<const CostTerm*> out;
        for (const CostTerm& t : cost_terms())
            if (t.in_tuning) out.push_back(&t);
        return out;
    }();
    return terms;
}

namespace {

std::size_t tuning_index(std::string_view name) {
    const std::vector<const CostTerm*>& terms = tuning_terms();
    for (std::size_t i = 0; i < terms.size(); ++i)
        if (terms[i]->name == name) return i;
    throw std::logic_error("a tuning's cost model has no term " + std::string(name));
}

}  // namespace

double fitted_value(const std::vector<Coefficient>& fitted, const std::string& name, const std::string& category) {
    const std::string copy = name + "[" + category + (category.empty() ? "" : "]");
    for (const Coefficient& c : fitted)
        if (c.name == name || c.name.compare(0, copy.size(), copy) == 0) return c.value;
    return 0.0;
}

CostCoefficients::CostCoefficients() : values(tuning_terms().size(), 0.0) {}

double CostCoefficients::operator[](std::string_view name) const { return values[tuning_index(name)]; }
double& CostCoefficients::operator[](std::string_view name) { return values[tuning_index(name)]; }

double CostCoefficients::per_ray(const FrameObservation& f) const {
    double sum = 0;
    for (std::size_t i = 0; i < values.size(); ++i) sum += values[i] * term_value(*tuning_terms()[i], f);
    return sum;
}

CostCoefficients CostCoefficients::from_fit(const std::vector<Coefficient>& fitted, const std::string& category) {
    CostCoefficients c;
    for (std::size_t i = 0; i < c.values.size(); ++i)
        c.values[i] = fitted_value(fitted, tuning_terms()[i]->name, category);
    return c;
}

nlohmann::json CostCoefficients::to_json() const {
    nlohmann::json j{{"model", model}};
    for (std::size_t i = 0; i < values.size(); ++i) j[tuning_terms()[i]->name] = values[i];
    return j;
}

CostCoefficients CostCoefficients::from_json(const nlohmann::json& j, const std::string& where) {
    if (!j.is_object()) throw InputError(where + ": a cost model must be an object");
    CostCoefficients c;
    // The terms every tuning has first, so a file missing several names the oldest one.
    for (const bool optional : {false, true})
        for (std::size_t i = 0; i < c.values.size(); ++i) {
            const CostTerm& t = *tuning_terms()[i];
            if (t.optional_in_json != optional) continue;
            if (!j.contains(t.name)) {
                if (optional) continue;  // written before the term existed: its model did not price it
                throw InputError(where + ": cost model coefficient " + t.name + " is missing or not a finite number");
            }
            if (!j[t.name].is_number() || !std::isfinite(j[t.name].get<double>()))
                throw InputError(where + ": cost model coefficient " + t.name +
                                 (optional ? " is not a finite number" : " is missing or not a finite number"));
            c.values[i] = j[t.name].get<double>();
        }
    if (j.contains("model") && j["model"].is_string()) c.model = j["model"].get<std::string>();
    return c;
}

}  // namespace rcb

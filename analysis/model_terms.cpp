#include "analysis/model_terms.h"

#include <cmath>
#include <stdexcept>

#include "analysis/linear_fit.h"
#include "core/base/error.h"
#include "core/accel/counter_fields.h"
#include "core/sim/simulator.h"
#include "runner/calibration.h"

namespace rcb {

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
        // (branches guessed wrong, nodes not in L1); N_MP from core/accel/outcome_predictor.h.
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
        // (N_MISS from core/accel/cache_model.h). Rays spread over a scene pay it; rays aimed at one
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
        // What a tree step costs beyond a missed node box when the box is hit: children pushed and fetched.
        {.name = "C_TH",
         .target = raycast,
         .counters = {"N_TH"},
         .unit = "ns per node box hit",
         .in_tuning = true,
         .traversal = true},
        // What a reported hit costs beyond its box test (its entry in the ray's list; a grid's dropped
        // hits, N_DUP, are left out: docs/model.md). Eq. 5.3 prices true and false positives alike;
        // the calibration's stack and cluster pin it apart from C_RB where they can (fit_calibration).
        {.name = "C_HIT",
         .target = raycast,
         .counters = {"N_TP"},
         .unit = "ns per reported hit",
         .prior = true,
         .in_tuning = true,
         .optional_in_json = true},
        {.name = "C_MEM",
         .target = raycast,
         .counters = {"MB"},
         .unit = "ns per ray per MiB of the structure",
         .when_absent = keep,
         .in_tuning = true},
        // Tests and steps beyond each cache level the working set leaves, weighted by their in-cache
        // (calibration) costs: the coefficient is the extra fraction of that cost.
        {.name = "slow>L",
         .target = raycast,
         .counters = {},
         .unit = "fraction of the in-cache cost",
         .per_tier = true,
         .weighted_by = {"C_RB", "C_T"}},
        {.name = "c_insert", .target = update, .counters = {"N_INS"}, .unit = "ns per insert", .operation = true},
        {.name = "c_remove", .target = update, .counters = {"N_REM"}, .unit = "ns per remove", .operation = true},
        {.name = "c_move", .target = update, .counters = {"N_MOV"}, .unit = "ns per move", .operation = true},
        {.name = "c_object", .target = update, .counters = {"N_OBJ"}, .unit = "ns per object", .when_absent = keep},
        {.name = "c_frame", .target = update, .counters = {}, .unit = "ns per frame", .when_absent = keep},
        // One price for any change: where a run mixes the operations in one proportion (the
        // thesis' 1% dynamics everywhere) their own costs cannot be told apart.
        {.name = "c_change",
         .target = update,
         .counters = {"N_INS", "N_REM", "N_MOV"},
         .unit = "ns per change",
         .when_absent = keep},
        // The update's footprint: what a cell, entry or node written costs (Structure::writes). A
        // long object spans many cells, a change that leaves its leaf reinserts along a path; the
        // changes alone cannot see either.
        {.name = "c_write", .target = update, .counters = {"N_UW"}, .unit = "ns per cell, entry or node written"},
        // A change that touches cells or nodes no longer cached.
        {.name = "c_change>L",
         .target = update,
         .counters = {},
         .unit = "ns per change beyond the cache",
         .per_tier = true,
         .weighted_by = {"c_change"}},
    };
    return terms;
}

const std::vector<ModelForm>& model_forms() {
    using enum Target;
    static const std::vector<ModelForm> forms{
        // Ray cast. C_RO is in every form where shapes were tested: a form without it would charge
        // the shape tests to the box tests (eq. 5.3).
        {"no-prep", raycast, {"C_RB", "C_T", "C_RO"}},
        {"eq5.4", raycast, {"C_RB", "C_T", "C_RO", "C_PREP"}},
        {"with-coherence", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP"}, {"C_MP"}},
        {"with-misses", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MISS"}, {"C_MISS"}},
        {"with-node-hits", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_TH"}, {"C_TH"}},
        {"with-hits", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_HIT"}, {"C_HIT"}},
        {"with-memory", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MEM"}},
        {"memory-hierarchy", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "slow>L"}},
        {"coherence-hierarchy", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP", "slow>L"}, {"C_MP"}},
        // Unpredicted steps and box hits: where a grid meets long objects again cell after cell.
        {"coherence-hits", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP", "C_HIT"}, {"C_MP", "C_HIT"}},
        {"coherence-misses", raycast, {"C_RB", "C_T", "C_RO", "C_PREP", "C_MP", "C_MISS"}, {"C_MP", "C_MISS"}},
        {"per-category", raycast, {"C_RB", "C_T", "C_RO", "C_PREP"}, {}, Split::by_category},
        // Update: per change, per change and cell or node written, per operation, with a per-object
        // (rebuild) cost, beyond the caches, and each configuration its own (an incremental and a
        // rebuilding mode of one structure).
        {"per-change", update, {"c_change", "c_frame"}, {"c_change"}},
        {"per-write", update, {"c_change", "c_write", "c_frame"}, {"c_change", "c_write"}},
        {"per-operation", update, {"c_insert", "c_remove", "c_move", "c_frame"}},
        {"write-rebuild", update, {"c_change", "c_write", "c_frame", "c_object"}, {"c_change", "c_write"}},
        {"with-rebuild", update, {"c_insert", "c_remove", "c_move", "c_frame", "c_object"}},
        {"change-hierarchy", update, {"c_change", "c_frame", "c_change>L"}, {"c_change"}},
        {"update-hierarchy", update, {"c_insert", "c_remove", "c_move", "c_frame", "c_change>L"}, {"c_change"}},
        {"per-configuration-change", update, {"c_change", "c_frame", "c_object"}, {"c_change"}, Split::by_params},
        {"per-configuration", update, {"c_insert", "c_remove", "c_move", "c_frame", "c_object"}, {}, Split::by_params},
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

FrameObservation observation_of(const FrameResult& frame, double objects) {
    FrameObservation o;
    o.rays = frame.rays;
    o.raycast_ns = double(frame.raycast_ns);
    o.update_ns = double(frame.update_ns);
    for (const FrameCounter& c : frame_counters()) {
        const double raw = c.counted ? double(frame.counters.*(c.counted)) : c.simulated ? c.simulated(frame) : objects;
        switch (c.scale) {
            case CounterScale::per_ray:
                o.*(c.field) = frame.rays > 0 ? raw / frame.rays : 0.0;
                break;
            case CounterScale::mebibytes:
                o.*(c.field) = raw / (1024.0 * 1024.0);
                break;
            case CounterScale::as_is:
                o.*(c.field) = raw;
                break;
        }
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

#include "tuner/advise.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <ostream>

#include "core/base/error.h"
#include "core/base/json_input.h"
#include "core/base/number_text.h"
#include "accel/narrow/narrow_phase.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "runner/experiment.h"

namespace rcb {

using json = nlohmann::json;

CategoryChoice choose_category(const std::string& tuning, const json& t, const Recording& scene) {
    if (!t.is_object() || !t.contains("scene_categories"))
        throw InputError(tuning +
                         ": has no scene categories to match a scene to (written by an older rcbench tune); give "
                         "--category or tune again");
    const SceneClustering clustering = SceneClustering::from_json(t["scene_categories"], tuning);
    CategoryChoice c;
    c.features = compute_scene_features(scene);
    c.match = nearest_category(clustering, c.features);
    c.category = clustering.categories[c.match.category].name;
    c.explanation = explain_match(clustering, c.match);
    return c;
}

std::string searched_text(const json& p) {
    std::string out;
    if (p.is_object())
        for (const auto& [k, v] : p.items())
            out += (out.empty() ? "" : " ") + k + "=" + (v.is_string() ? v.get<std::string>() : v.dump());
    return out;
}

AdviseMethod parse_advise_method(std::string_view text) {
    if (text == "auto") return AdviseMethod::automatic;
    if (text == "category") return AdviseMethod::category;
    if (text == "model") return AdviseMethod::model;
    throw InputError("--method: expected auto, category or model, got " + quoted_excerpt(std::string(text)));
}

std::string_view method_name(ParameterMethod method) { return method == ParameterMethod::model ? "model" : "category"; }

std::ostream& operator<<(std::ostream& out, ParameterMethod method) { return out << method_name(method); }

namespace {

/// The space a tuning recorded, each level checked against the structure's parameters (a level the
/// structure refuses would fail minutes into the advice otherwise).
std::vector<SearchDimension> read_space(const json& j, const StructureInfo& info, const std::string& where) {
    std::vector<SearchDimension> dims;
    std::size_t size = 1;
    if (!j.is_array()) throw InputError(where + ": space must be a list of {\"name\", \"levels\"}");
    for (std::size_t i = 0; i < j.size(); ++i) {
        const std::string at = where + ".space[" + std::to_string(i) + "]";
        if (!j[i].is_object() || !j[i].contains("name") || !j[i]["name"].is_string() || !j[i].contains("levels") ||
            !j[i]["levels"].is_array() || j[i]["levels"].empty())
            throw InputError(at + ": expected {\"name\": NAME, \"levels\": [at least one value]}");
        SearchDimension d{j[i]["name"].get<std::string>(), {}};
        for (const json& level : j[i]["levels"]) {
            info.complete(json{{d.name, level}}, at + ".levels");
            d.levels.push_back(level);
        }
        size *= d.levels.size();
        if (size > kMaxPlanCells)
            throw InputError(at + ": the space has more than " + std::to_string(kMaxPlanCells) + " configurations");
        dims.push_back(std::move(d));
    }
    return dims;
}

std::map<std::string, TunedStructure> read_category(const json& t, const std::string& tuning,
                                                    const std::string& wanted) {
    std::map<std::string, TunedStructure> tuned;
    bool found = false;
    try {
        for (const auto& c : t.at("categories")) {
            if (c.at("category").get<std::string>() != wanted) continue;
            found = true;
            for (const auto& s : c.at("structures")) {
                const std::string name = s.at("structure").get<std::string>();
                const std::string where = tuning + ": category \"" + wanted + "\", " + name;
                const StructureInfo* found_info = nullptr;
                try {
                    found_info = &find_structure(name);
                } catch (const InputError& e) {
                    throw InputError(tuning + ": category \"" + wanted + "\": " + e.what());
                }
                const StructureInfo& info = *found_info;
                TunedStructure ts;
                // Every parameter, those recorded only away from their default (the query level)
                // included, so that a space searching them finds the category's level.
                ts.params = info.defaults();
                for (const auto& [k, v] : s.at("best").at("params").items()) ts.params[k] = v;
                if (s.contains("space")) ts.space = read_space(s["space"], info, where);
                if (s.contains("cost_model")) ts.model = CostCoefficients::from_json(s["cost_model"], where);
                if (s.contains("update_model")) ts.update = UpdatePrices::from_json(s["update_model"], where);
                tuned[name] = std::move(ts);
            }
        }
    } catch (const json::exception&) {  // a missing key or a value of the wrong type
        throw InputError(tuning + ": not a tuning result (rcbench tune writes them)");
    }
    if (!found) throw InputError(tuning + ": no category \"" + wanted + "\"");
    return tuned;
}

json searched_of(const json& params, const std::vector<SearchDimension>& space) {
    json p = json::object();
    for (const SearchDimension& d : space)
        if (params.contains(d.name)) p[d.name] = params[d.name];
    return p;
}

/// The same point of a space, whatever the spelling of its numbers (4 and 4.0).
bool same_point(const json& a, const json& b, const std::vector<SearchDimension>& space) {
    for (const SearchDimension& d : space)
        if (!a.contains(d.name) || !b.contains(d.name) || a[d.name] != b[d.name]) return false;
    return true;
}

std::string ms_text(double ms) { return fixed(ms, 4); }

/// Why a tuned structure's parameters come from `method`, in one sentence.
std::string method_reason(AdviseMethod asked, ParameterMethod method, const std::string& structure,
                          const std::string& category) {
    if (method == ParameterMethod::model)
        return asked == AdviseMethod::model
                   ? "--method model"
                   : "the tuning holds a cost model for " + structure + " in category " + category +
                         ", so this scene's own counters decide instead of the best of the "
                         "category's scenes";
    return asked == AdviseMethod::category
               ? "--method category"
               : "the tuning holds no cost model for " + structure + " in category " + category +
                     " (tuned by an older rcbench, or too few configurations to fit "
                     "one), so the category's parameters are used as they are";
}

std::string category_summary(const ParameterChoice& pc, const std::string& category) {
    return pc.structure + ": " + searched_text(pc.category_searched) + ", category " + category +
           "'s tuned parameters (" + pc.why + ").";
}

std::string model_summary(const ParameterChoice& pc, const std::string& category, const std::string& algorithm,
                          std::uint32_t verify_top) {
    std::string measured_text;
    for (const ModelCandidate& c : pc.candidates) {
        if (!c.measured) continue;
        measured_text += std::string(measured_text.empty() ? "" : ", ") + searched_text(c.searched) + " " +
                         ms_text(c.measured->ms) + " ms" +
                         (c.predicted_ms ? " (predicted " + ms_text(*c.predicted_ms) + ")" : "") +
                         (c.is_category ? " [category's]" : "");
    }
    const std::string update = pc.budget.replays_update_timed > 0
                                   ? "each replay timed the scene's update (the tuning holds no update prices)"
                                   : "the update predicted from each frame's changes and writes, nothing timed";
    return pc.structure + ": " + searched_text(pc.chosen_searched) + " by the cost model of category " + category +
           ", " + pc.model + ", on this scene's counters (" + pc.why + "): " + std::to_string(pc.replays) + " of " +
           std::to_string(pc.space_size) + " configurations replayed (" + algorithm + "; " + update + "); " +
           (verify_top > 0
                ? "measured " + measured_text +
                      (pc.refined > 0 ? "; " + std::to_string(pc.refined) + " of them by the measured descent" : "") +
                      "; the fastest measured is advised."
                : "the predicted best is advised, measured on nothing (--verify-top 0, the pure model).");
}

}  // namespace

bool AdviceRow::priced() const { return std::isfinite(cost.ms); }

json TunedStructure::with(const StructureInfo& info, const json& searched, const std::string& where) const {
    json p = params;
    for (const auto& [k, v] : searched.items()) p[k] = v;
    return info.complete(p, where);
}

TuneCategory advise_scene(const std::string& scene) {
    TuneCategory category;
    category.name = std::filesystem::path(scene).stem().string();
    SceneSpec spec;
    spec.name = category.name;
    spec.path = scene;
    spec.key = {{"advise", scene}};
    const bool csv = scene.size() >= 4 && scene.compare(scene.size() - 4, 4, ".csv") == 0;
    spec.source = csv ? SceneSpec::Source::import : SceneSpec::Source::recording;
    if (csv) spec.settings.frames = 10;
    category.scenes.push_back(spec);
    return category;
}

TuningSelection select_tuning(const AdviseOptions& o, const TuneCategory& scene) {
    TuningSelection selection;
    selection.category = o.category;
    if (o.tuning.empty()) return selection;
    const json t = parse_json_document(read_text_file(o.tuning), o.tuning);
    if (selection.category.empty()) {
        selection.chosen = choose_category(o.tuning, t, recording_of(scene.scenes.front()));
        selection.category = selection.chosen->category;
    }
    selection.tuned = read_category(t, o.tuning, selection.category);
    if (t.contains("budget") && t["budget"].is_number_unsigned() && t["budget"].get<std::size_t>() > 0)
        selection.budget = std::min<std::size_t>(t["budget"].get<std::size_t>(), 10'000);
    if (o.replays) selection.budget = *o.replays;
    if (t.contains("seed") && t["seed"].is_number_unsigned()) selection.seed = t["seed"].get<std::uint64_t>();
    return selection;
}

ParameterPlan plan_parameters(const TuningSelection& selection, AdviseMethod method, bool exhaustive,
                              const std::string& tuning) {
    ParameterPlan plan;
    const std::string& category = selection.category;
    for (const StructureInfo& info : structure_registry()) {
        auto it = selection.tuned.find(info.name);
        if (it == selection.tuned.end()) {
            plan.structures.push_back({&info, info.complete(json::object(), info.name)});
            continue;
        }
        const TunedStructure& ts = it->second;
        plan.structures.push_back({&info, info.complete(ts.params, tuning)});
        ParameterChoice pc;
        pc.structure = info.name;
        pc.space = ts.space;
        pc.category_searched = searched_of(ts.params, ts.space);
        const bool can_model = ts.model && !ts.space.empty();
        if (method == AdviseMethod::model && !can_model)
            throw InputError(tuning + ": category \"" + category + "\" holds no cost model and space for " + info.name +
                             " (tuned by an older rcbench, or too few configurations to fit one); use --method "
                             "category or tune again");
        if (exhaustive && ts.space.empty())
            throw InputError(tuning + ": category \"" + category + "\" records no search space for " + info.name +
                             " (tuned by an older rcbench); --exhaustive needs one: tune again");
        pc.method = method == AdviseMethod::category || !can_model ? ParameterMethod::category : ParameterMethod::model;
        if (pc.method == ParameterMethod::model) pc.model = ts.model->model;
        pc.why = method_reason(method, pc.method, info.name, category);
        pc.chosen_searched = pc.category_searched;
        plan.choices.push_back(std::move(pc));
    }
    return plan;
}

std::optional<ReplayCounts> ReplayLog::find(const json& searched, const std::vector<SearchDimension>& space) const {
    for (const auto& [q, c] : entries)
        if (same_point(searched, q, space)) return c;
    return std::nullopt;
}

ModelRanking rank_by_model(const std::vector<SearchDimension>& space, const json& start, std::size_t budget,
                           std::uint64_t seed, const ReplayPrediction& predict) {
    ModelRanking ranking;
    ranking.search = search_levels(
        space,
        [&](const json& p) {
            ReplayCounts counts;
            const double ms = predict(p, counts);
            ranking.replays.entries.push_back({p, counts});
            return ms;
        },
        budget, seed, start);
    return ranking;
}

std::vector<std::size_t> prediction_order(const std::vector<Evaluation>& evaluations) {
    std::vector<std::size_t> order(evaluations.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return evaluations[a].cost < evaluations[b].cost; });
    return order;
}

ModelEvidence verify_candidates(const ModelRanking& ranking, const std::vector<SearchDimension>& space,
                                const json& category_searched, std::uint32_t verify_top,
                                const SceneMeasurement& measure) {
    ModelEvidence e;
    e.replays = ranking.replays;
    const std::vector<Evaluation>& evaluations = ranking.search.evaluations;
    // The best predictions are measured, one per structure in effect: a configuration that
    // counts exactly as one measured already is the same structure and tells nothing new.
    const std::size_t to_measure = verify_top;
    for (const std::size_t k : prediction_order(evaluations)) {
        ModelCandidate c{evaluations[k].params, evaluations[k].cost, std::nullopt, false};
        c.is_category = same_point(c.searched, category_searched, space);
        const std::optional<ReplayCounts> counts = e.replays.find(c.searched, space);
        const bool repeat =
            counts && std::find(e.measured_counts.begin(), e.measured_counts.end(), counts) != e.measured_counts.end();
        if (e.measured_counts.size() < to_measure && !repeat) {
            c.measured = measure(c.searched);
            e.measured_counts.push_back(counts);
        }
        e.candidates.push_back(std::move(c));
    }
    // The category's parameters compete unless only the prediction decides (--verify-top 0).
    if (verify_top == 0) return e;
    auto category =
        std::find_if(e.candidates.begin(), e.candidates.end(), [](const ModelCandidate& c) { return c.is_category; });
    if (category == e.candidates.end()) {
        e.candidates.push_back({category_searched, std::nullopt, std::nullopt, true});
        category = e.candidates.end() - 1;
    }
    if (!category->measured) {
        category->measured = measure(category_searched);
        e.measured_counts.push_back(e.replays.find(category_searched, space));
    }
    return e;
}

bool measured_faster(const MeasuredCost& a, const MeasuredCost& b, const AccuracyConstraint& accuracy) {
    const bool ma = accuracy.met_by(a.accuracy), mb = accuracy.met_by(b.accuracy);
    return ma != mb ? ma : a.ms < b.ms;
}

std::vector<json> descent_neighbours(const std::vector<SearchDimension>& space, const json& from, std::size_t stride) {
    std::vector<json> out;
    for (const SearchDimension& d : space) {
        if (!from.contains(d.name)) continue;
        const auto at = std::find(d.levels.begin(), d.levels.end(), from[d.name]);
        if (at == d.levels.end()) continue;
        for (const std::ptrdiff_t step : {std::ptrdiff_t(stride), -std::ptrdiff_t(stride)}) {
            const std::ptrdiff_t i = (at - d.levels.begin()) + step;
            if (i < 0 || i >= std::ptrdiff_t(d.levels.size())) continue;
            json q = from;
            q[d.name] = d.levels[std::size_t(i)];
            out.push_back(std::move(q));
        }
    }
    return out;
}

void refine_by_descent(ModelEvidence& e, const DescentSettings& s, const ReplayPrediction& predict,
                       const SceneMeasurement& measure) {
    auto faster = [&](std::size_t a, std::size_t b) {
        return measured_faster(*e.candidates[a].measured, *e.candidates[b].measured, s.accuracy);
    };
    std::optional<std::size_t> current;  // into e.candidates: the fastest measured
    for (std::size_t k = 0; k < e.candidates.size(); ++k)
        if (e.candidates[k].measured && (!current || faster(k, *current))) current = k;
    if (!current) return;
    // Measures `q` unless it is a structure measured already; true when it is the fastest now.
    auto probe = [&](const json& q) {
        std::optional<ReplayCounts> counts = e.replays.find(q, s.space);
        std::optional<double> predicted;
        if (!counts) {
            ReplayCounts replayed;
            predicted = predict(q, replayed);
            e.replays.entries.push_back({q, replayed});
            counts = replayed;
        }
        if (std::find(e.measured_counts.begin(), e.measured_counts.end(), counts) != e.measured_counts.end())
            return false;
        std::size_t k = 0;
        while (k < e.candidates.size() && !same_point(e.candidates[k].searched, q, s.space)) ++k;
        if (k == e.candidates.size())
            e.candidates.push_back({q, predicted, std::nullopt, same_point(q, s.category_searched, s.space)});
        e.candidates[k].measured = measure(q);
        e.measured_counts.push_back(counts);
        ++e.refined;
        if (!faster(k, *current)) return false;
        current = k;
        return true;
    };
    auto step_from = [&](const json& from, std::size_t stride) {
        for (const json& q : descent_neighbours(s.space, from, stride)) {
            if (e.refined == s.refine) return false;
            if (probe(q)) return true;
        }
        return false;
    };
    while (e.refined < s.refine) {
        const json from = e.candidates[*current].searched;
        if (!step_from(from, 1) && !step_from(from, 2)) break;
    }
}

void order_candidates(std::vector<ModelCandidate>& candidates, const AccuracyConstraint& accuracy) {
    std::stable_sort(candidates.begin(), candidates.end(), [&](const ModelCandidate& a, const ModelCandidate& b) {
        if (a.measured.has_value() != b.measured.has_value()) return a.measured.has_value();
        if (!a.measured) return a.predicted_ms.value_or(INFINITY) < b.predicted_ms.value_or(INFINITY);
        return measured_faster(*a.measured, *b.measured, accuracy);
    });
}

std::optional<TableChoice> advise_on_table(const ModelRanking& ranking, const DescentSettings& settings,
                                           std::uint32_t verify_top, const std::vector<json>& configurations,
                                           const std::vector<MeasuredCost>& table, const ReplayPrediction& predict) {
    std::vector<bool> read(configurations.size(), false);
    bool missing = false;
    const SceneMeasurement from_table = [&](const json& searched) {
        for (std::size_t i = 0; i < configurations.size(); ++i)
            if (same_point(configurations[i], searched, settings.space)) {
                read[i] = true;
                return table[i];
            }
        missing = true;
        MeasuredCost none;
        none.ms = INFINITY;
        return none;
    };
    ModelEvidence e = verify_candidates(ranking, settings.space, settings.category_searched, verify_top, from_table);
    if (verify_top > 0) refine_by_descent(e, settings, predict, from_table);
    order_candidates(e.candidates, settings.accuracy);
    if (missing || e.candidates.empty()) return std::nullopt;
    return TableChoice{e.candidates.front().searched, std::size_t(std::count(read.begin(), read.end(), true)),
                       e.replays.entries.size()};
}

RowPlan plan_rows(const std::vector<StructurePlan>& structures, const std::vector<ParameterChoice>& choices,
                  const AccuracyConstraint& accuracy) {
    RowPlan plan;
    for (const auto& [info, p] : structures) {
        // A plain reference for the lambda: clang 14 cannot capture a structured binding.
        const std::string& name = info->name;
        const bool is_tuned = std::any_of(choices.begin(), choices.end(),
                                          [&](const ParameterChoice& pc) { return pc.structure == name; });
        plan.params.push_back(p);
        plan.rows.push_back({info->name, p.dump(), {}, is_tuned});
        // Inexact answers allowed: the same configuration at the other query levels competes too
        // (a tuned level is kept as the tuning chose it).
        if (accuracy.allows_inexact() && query_level_of(p) == QueryLevel::boxes)
            for (const char* level : {"candidates", "shapes"}) {
                json q = p;
                q["query"] = level;
                plan.params.push_back(info->complete(q, "advise"));
                plan.rows.push_back({info->name, plan.params.back().dump(), {}, is_tuned});
            }
    }
    return plan;
}

void measure_rows(RowPlan& plan, const std::vector<ParameterChoice>& choices,
                  const std::function<MeasuredCost(const std::string&, const json&)>& measure,
                  const std::function<void(const std::string&)>& progress) {
    // The model method's measured choice, by structure; its row is the first of the structure's
    // (the later ones are the other query levels).
    std::map<std::string, MeasuredCost> already;
    for (const ParameterChoice& pc : choices)
        for (const ModelCandidate& c : pc.candidates)
            if (c.measured && same_point(c.searched, pc.chosen_searched, pc.space)) already[pc.structure] = *c.measured;
    std::map<std::string, std::string> chosen_params;  // structure → its first row's params
    for (const AdviceRow& r : plan.rows) chosen_params.emplace(r.structure, r.params);
    for (std::size_t i = 0; i < plan.rows.size(); ++i) {
        AdviceRow& row = plan.rows[i];
        auto it = already.find(row.structure);
        if (it != already.end() && chosen_params.at(row.structure) == row.params) {
            row.cost = it->second;
            continue;
        }
        if (progress) progress(row.structure);
        row.cost = measure(row.structure, plan.params[i]);
    }
}

void predict_rows(RowPlan& plan, const std::vector<ParameterChoice>& choices) {
    std::map<std::string, std::string> first_params;  // structure → its first row's params (the advised)
    for (const AdviceRow& r : plan.rows) first_params.emplace(r.structure, r.params);
    for (std::size_t i = 0; i < plan.rows.size(); ++i) {
        AdviceRow& row = plan.rows[i];
        row.cost = MeasuredCost{};
        row.cost.ms = INFINITY;  // unpriced, unless the model predicted this configuration
        row.cost.update_ms = row.cost.raycast_ms = row.cost.mad = row.cost.memory_bytes = NAN;
        row.cost.accuracy.exact_level = query_level_of(plan.params[i]) != QueryLevel::candidates;
        if (first_params.at(row.structure) != row.params) continue;
        for (const ParameterChoice& pc : choices) {
            if (pc.structure != row.structure || pc.method != ParameterMethod::model) continue;
            for (const ModelCandidate& c : pc.candidates)
                if (c.predicted_ms && same_point(c.searched, pc.chosen_searched, pc.space)) {
                    row.cost.ms = *c.predicted_ms;
                    row.predicted = true;
                    break;
                }
        }
    }
}

ExhaustiveAdvice compare_exhaustively(const ParameterChoice& pc, const std::vector<json>& configurations,
                                      const std::vector<MeasuredCost>& table, const AccuracyConstraint& accuracy,
                                      const Rescore& rescore, std::uint64_t seed,
                                      const std::vector<std::size_t>& class_of,
                                      const std::optional<TableChoice>& on_table) {
    ExhaustiveAdvice ex;
    ex.structure = pc.structure;
    ex.budget = pc.budget;
    MethodInputs in;
    in.space = pc.space, in.configurations = configurations, in.advised = pc.chosen_searched;
    in.category = pc.category_searched, in.predicted_best = pc.predicted_best;
    in.budget = pc.budget.timed, in.replays = pc.budget.replays, in.seed = seed;
    in.advised_on_table = on_table;
    in.class_of = class_of;
    for (const MeasuredCost& c : table) in.table.push_back(constrained_cost(c, accuracy));
    ex.advised_searched = pc.chosen_searched;
    ex.category_searched = pc.category_searched;
    ex.configurations = configurations.size();
    const MethodComparison m = compare_methods(in, [&](const std::vector<std::size_t>& indices) {
        std::vector<double> out;
        for (const MeasuredCost& c : rescore(indices)) out.push_back(constrained_cost(c, accuracy));
        ex.rescored = indices.size();
        return out;
    });
    ex.methods = m.methods;
    ex.best_searched = configurations.empty() ? json() : configurations[m.optimum];
    ex.best_table_ms = m.optimum_table_ms, ex.best_ms = m.optimum_ms;
    ex.advised_ms = ex.category_ms = NAN;  // a configuration the space lacks has no row
    for (const MethodOutcome& o : ex.methods) {
        if (o.method == "advise") ex.advised_ms = o.ms;
        if (o.method == "category") ex.category_ms = o.ms;
    }
    return ex;
}

namespace {

/// Every configuration advise timed, by structure, once per measurement (its budget's source).
using MeasurementLog = std::map<std::string, std::vector<json>>;

/// What advise measures with: the scene and the options' repetitions, warm-up and accuracy; each
/// measurement is logged (a pointer: the meter is copied into std::functions).
struct SceneMeter {
    const TuneCategory& scene;
    const AdviseOptions& options;
    MeasurementLog* log;
    bool verify() const { return options.accuracy.needs_verification(); }
    MeasuredCost operator()(const std::string& structure, const json& params) const {
        (*log)[structure].push_back(params);
        return measure(scene, structure, params, options.warmup, options.repetitions, verify());
    }
};

/// A tuned structure's budget: its logged measurements (distinct configurations, and their
/// repetitions), the replays counted while advising, and its space's size (0: none recorded).
AdviseBudget budget_of(const ParameterChoice& pc, const MeasurementLog& log, std::uint32_t repetitions) {
    AdviseBudget b;
    b.replays = pc.budget.replays;
    b.replays_update_timed = pc.budget.replays_update_timed;
    b.space = pc.space.empty() ? 0 : 1;
    for (const SearchDimension& d : pc.space) b.space *= d.levels.size();
    const auto it = log.find(pc.structure);
    if (it == log.end()) return b;
    std::vector<json> distinct;
    for (const json& p : it->second)
        if (std::find(distinct.begin(), distinct.end(), p) == distinct.end()) distinct.push_back(p);
    b.timed = distinct.size();
    b.timed_measurements = it->second.size() * repetitions;
    return b;
}

/// The model method for one tuned structure: its candidates predicted, verified, refined by the
/// measured descent and ordered; the chosen parameters go into `plan`.
void advise_by_model(ParameterChoice& pc, const TunedStructure& ts, StructurePlan& plan,
                     const TuningSelection& selection, const SceneMeter& meter) {
    const AdviseOptions& o = meter.options;
    const StructureInfo& info = *plan.info;
    const CostCoefficients& model = *ts.model;
    const UpdatePrices* update = ts.update ? &*ts.update : nullptr;  // none: the replays time the update
    const ReplayPrediction predict = [&](const json& searched, ReplayCounts& counts) {
        ++pc.budget.replays;
        if (!update) ++pc.budget.replays_update_timed;
        return predict_cost(model, meter.scene, pc.structure, searched, o.warmup, &counts, update);
    };
    const SceneMeasurement measure_at = [&](const json& searched) {
        return meter(pc.structure, ts.with(info, searched, o.tuning));
    };
    pc.ranking = std::make_shared<const ModelRanking>(
        rank_by_model(pc.space, pc.category_searched, selection.budget, selection.seed, predict));
    const ModelRanking& ranking = *pc.ranking;
    pc.replays = ranking.search.evaluations.size();
    pc.space_size = ranking.search.space_size;
    if (!ranking.search.evaluations.empty())
        pc.predicted_best = ranking.search.evaluations[prediction_order(ranking.search.evaluations).front()].params;
    ModelEvidence evidence = verify_candidates(ranking, pc.space, pc.category_searched, o.verify_top, measure_at);
    if (o.verify_top > 0)
        refine_by_descent(evidence, {pc.space, pc.category_searched, o.refine, o.accuracy}, predict, measure_at);
    order_candidates(evidence.candidates, o.accuracy);
    pc.candidates = std::move(evidence.candidates);
    pc.refined = evidence.refined;
    pc.chosen_searched = pc.candidates.front().searched;
    plan.params = ts.with(info, pc.chosen_searched, o.tuning);
    pc.summary = model_summary(pc, selection.category, ranking.search.algorithm, o.verify_top);
}

/// --exhaustive: every configuration of each tuned structure's space measured on the scene.
std::vector<ExhaustiveAdvice> check_exhaustively(const std::vector<ParameterChoice>& choices,
                                                 const TuningSelection& selection, const SceneMeter& meter) {
    const AdviseOptions& o = meter.options;
    std::vector<ExhaustiveAdvice> out;
    for (const ParameterChoice& pc : choices) {
        if (o.progress) o.progress(pc.structure + " (every configuration)");
        const TunedStructure& ts = selection.tuned.at(pc.structure);
        const StructureInfo& info = find_structure(pc.structure);
        const std::vector<json> all = enumerate_space(pc.space);
        std::vector<json> full_params;
        for (const json& p : all) full_params.push_back(ts.with(info, p, o.tuning));
        // The table the baselines and advise-table choose on, whose best is the scene's optimum.
        const std::vector<MeasuredCost> table =
            measure_interleaved(meter.scene, pc.structure, full_params, o.warmup, o.repetitions, meter.verify());
        // advise replayed the scene: the baselines get as many replays, which tell them the
        // structures in effect; the space is replayed once here (untimed with the update's prices)
        // to know every configuration's counts, and advise-table's steps read their predictions.
        std::vector<std::size_t> class_of;
        std::optional<TableChoice> on_table;
        if (pc.ranking) {
            const CostCoefficients& model = *ts.model;
            const SpaceSurvey survey = survey_space(all, model, [&](const json& p) {
                return counting_replay(meter.scene, pc.structure, p, o.warmup, ts.update ? &*ts.update : nullptr);
            });
            class_of = survey.class_of;
            // advise's own steps again, on the table: the same ranking, each timing read from it.
            const ReplayPrediction predict = [&](const json& searched, ReplayCounts& counts) {
                const std::size_t i = std::size_t(std::find(all.begin(), all.end(), searched) - all.begin());
                if (i == all.size()) return predict_cost(model, meter.scene, pc.structure, searched, o.warmup, &counts);
                counts = survey.replays[i].counts;
                return survey.predicted[i];
            };
            if (o.verify_top > 0)
                on_table = advise_on_table(*pc.ranking, {pc.space, pc.category_searched, o.refine, o.accuracy},
                                           o.verify_top, all, table, predict);
        }
        // The scoring pass, after every choice: each method's choice and the optimum re-measured.
        const Rescore rescore = [&](const std::vector<std::size_t>& indices) {
            std::vector<json> params;
            for (const std::size_t i : indices) params.push_back(full_params[i]);
            return measure_interleaved(meter.scene, pc.structure, params, o.warmup, o.repetitions, meter.verify());
        };
        out.push_back(compare_exhaustively(pc, all, table, o.accuracy, rescore, o.seed.value_or(selection.seed),
                                           class_of, on_table));
    }
    return out;
}

}  // namespace

Advice advise(const AdviseOptions& o) {
    const AdviseMethod method = parse_advise_method(o.method);
    if (o.tuning.empty() && !o.category.empty()) throw InputError("--category needs --tuning");
    if (o.tuning.empty() && o.exhaustive) throw InputError("--exhaustive needs --tuning");
    // The pure model times nothing on the scene, so nothing can verify an inexact answer.
    const bool pure = o.verify_top == 0;
    if (pure && o.accuracy.needs_verification())
        throw InputError(
            "--verify-top 0 (the pure model) times and verifies nothing on the scene, so it cannot "
            "judge --accuracy " +
            o.accuracy.text() + "; use --accuracy exact");
    if (!std::filesystem::is_regular_file(o.scene)) throw InputError(o.scene + ": no such file");
    TuneCategory scene = advise_scene(o.scene);
    scene.timing = o.timing;
    const TuningSelection selection = select_tuning(o, scene);
    try {
        check_warmup(o.warmup, recording_of(scene.scenes.front()).frames.size());
    } catch (const InputError& e) {
        throw InputError(o.scene + ": " + e.what());
    }
    // Every structure's parameters and method are checked before the first measurement, so a bad
    // tuning file or an impossible --method fails at once, not after minutes of measuring.
    ParameterPlan plan = plan_parameters(selection, method, o.exhaustive, o.tuning);

    // The model method: the category's cost model on this scene's counters picks the candidates,
    // measurements on the scene decide among them and the category's own parameters.
    MeasurementLog log;
    const SceneMeter meter{scene, o, &log};
    for (ParameterChoice& pc : plan.choices) {
        if (pc.method == ParameterMethod::category) {
            pc.summary = category_summary(pc, selection.category);
            continue;
        }
        if (o.progress) o.progress(pc.structure + " (cost model on the scene)");
        auto structure = std::find_if(plan.structures.begin(), plan.structures.end(),
                                      [&](const StructurePlan& s) { return s.info->name == pc.structure; });
        advise_by_model(pc, selection.tuned.at(pc.structure), *structure, selection, meter);
    }

    // Every structure measured at its parameters (the model method's choice measured already).
    Advice advice;
    advice.workload = scene_workload(recording_of(scene.scenes.front()));
    advice.workload_text = workload_summary(advice.workload, scene.scenes.front().source == SceneSpec::Source::import);
    advice.chosen = selection.chosen;
    RowPlan rows = plan_rows(plan.structures, plan.choices, o.accuracy);
    if (pure)
        predict_rows(rows, plan.choices);
    else
        measure_rows(rows, plan.choices, meter, o.progress);
    for (ParameterChoice& pc : plan.choices) pc.budget = budget_of(pc, log, o.repetitions);
    advice.baseline_seed = o.seed.value_or(selection.seed);
    advice.rows = std::move(rows.rows);
    advice.recommended = rank_advice(advice.rows, o.accuracy);
    if (o.exhaustive) advice.exhaustive = check_exhaustively(plan.choices, selection, meter);
    advice.parameters = std::move(plan.choices);
    return advice;
}

std::string workload_summary(const SceneWorkload& w, bool csv) {
    auto pct = [](double share) { return fixed(100 * share, 1) + "%"; };
    std::string text = "Workload per frame: " + fixed(w.rays_per_frame, 0) + " rays (" + w.kinds_text() + "), " +
                       fixed(w.changes_per_frame, 1) + " objects changed (p50 " + pct(w.changed_p50) + ", p90 " +
                       pct(w.changed_p90) + " of the live objects), a move " + fixed(w.move_median, 3) +
                       " of the object's longest edge (median; p90 " + fixed(w.move_p90, 3) + ").";
    text += csv ? " A boxes CSV has no motion or rays of its own: it is given 10 frames of 1% dynamics and 1000 "
                  "centre rays, so the advice weighs update against ray cast by those."
                : " Every cost below is this scene's own update plus ray cast per frame, measured on these frames "
                  "(the model method predicts it from counting replays of the same frames and rays), so update "
                  "and ray cast weigh as these counts and kinds make them.";
    return text;
}

std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy) {
    std::stable_sort(rows.begin(), rows.end(),
                     [](const AdviceRow& a, const AdviceRow& b) { return a.cost.ms < b.cost.ms; });
    std::optional<std::size_t> best;
    for (std::size_t i = 0; i < rows.size(); ++i) {
        rows[i].meets = rows[i].priced() && accuracy.met_by(rows[i].cost.accuracy);
        if (rows[i].meets && !best) best = i;
    }
    return best;
}

namespace {

json budget_json(const AdviseBudget& b) {
    return {{"timed", b.timed},
            {"timed_measurements", b.timed_measurements},
            {"replays", b.replays},
            {"replays_update_timed", b.replays_update_timed},
            {"space", b.space}};
}

json exhaustive_json(const ExhaustiveAdvice& e) {
    json methods = json::array();
    for (const MethodOutcome& m : e.methods)
        methods.push_back({{"method", m.method},
                           {"timed", m.timed},
                           {"replays", m.replays},
                           {"params", m.searched},
                           {"table_ms", m.table_ms},
                           {"ms", m.ms},
                           {"regret", m.regret}});
    return {{"structure", e.structure},
            {"configurations", e.configurations},
            {"best_params", e.best_searched},
            {"best_table_ms", e.best_table_ms},
            {"best_ms", e.best_ms},
            {"rescored", e.rescored},
            {"advised_params", e.advised_searched},
            {"advised_ms", e.advised_ms},
            {"advised_gap", e.advised_gap()},
            {"category_params", e.category_searched},
            {"category_ms", e.category_ms},
            {"category_gap", e.category_gap()},
            {"budget", budget_json(e.budget)},
            {"methods", methods}};
}

}  // namespace

json advice_json(const Advice& a, const AdviseOptions& o) {
    auto cost_json = [](const MeasuredCost& c) {
        json j = {{"ms", c.ms},
                  {"mad", c.mad},
                  {"update_ms", c.update_ms},
                  {"raycast_ms", c.raycast_ms},
                  {"memory_bytes", c.memory_bytes}};
        if (c.accuracy.verified) j["precision"] = c.accuracy.precision, j["recall"] = c.accuracy.recall;
        return j;
    };
    json j = {{"scene", o.scene},           {"tuning", o.tuning},
              {"method", o.method},         {"accuracy", o.accuracy.text()},
              {"category", nullptr},        {"parameters", json::array()},
              {"rows", json::array()},      {"recommended", nullptr},
              {"exhaustive", json::array()}};
    j["workload"] = a.workload.to_json();
    j["workload"]["summary"] = a.workload_text;
    if (a.chosen)
        j["category"] = {{"name", a.chosen->category},
                         {"distance", a.chosen->match.distance},
                         {"explanation", a.chosen->explanation},
                         {"features", a.chosen->features.to_json()}};
    else if (!o.category.empty())
        j["category"] = {{"name", o.category}, {"explanation", "--category"}};
    for (const ParameterChoice& pc : a.parameters) {
        json pj = {{"structure", pc.structure},
                   {"method", method_name(pc.method)},
                   {"why", pc.why},
                   {"category_params", pc.category_searched},
                   {"params", pc.chosen_searched},
                   {"summary", pc.summary},
                   {"budget", budget_json(pc.budget)},
                   {"candidates", json::array()}};
        if (pc.predicted_best) pj["predicted_best"] = *pc.predicted_best;
        if (pc.method == ParameterMethod::model)
            pj["model"] = pc.model, pj["replays"] = pc.replays, pj["space_size"] = pc.space_size,
            pj["refined"] = pc.refined;
        for (const ModelCandidate& c : pc.candidates) {
            json cj = {{"params", c.searched}, {"category", c.is_category}};
            if (c.predicted_ms) cj["predicted_ms"] = *c.predicted_ms;
            if (c.measured) cj["measured"] = cost_json(*c.measured);
            pj["candidates"].push_back(cj);
        }
        j["parameters"].push_back(pj);
    }
    for (const AdviceRow& r : a.rows) {
        json rj = {{"structure", r.structure}, {"params", json::parse(r.params)},
                   {"tuned", r.tuned},         {"meets", r.meets},
                   {"predicted", r.predicted}, {"cost", r.priced() ? cost_json(r.cost) : json(nullptr)}};
        j["rows"].push_back(rj);
    }
    if (a.recommended)
        j["recommended"] = {{"structure", a.rows[*a.recommended].structure},
                            {"params", json::parse(a.rows[*a.recommended].params)}};
    for (const ExhaustiveAdvice& e : a.exhaustive) j["exhaustive"].push_back(exhaustive_json(e));
    if (o.exhaustive) j["baseline_seed"] = a.baseline_seed;
    return j;
}

}  // namespace rcb

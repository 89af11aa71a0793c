#include "tuner/advise.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>

#include "core/base/error.h"
#include "core/base/json_input.h"
#include "core/base/number_text.h"
#include "core/accel/query_level.h"
#include "core/accel/registry.h"
#include "core/sim/simulator.h"
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

namespace {

/// What a tuning result holds for one structure of one category.
struct TunedStructure {
    json params;                            ///< the category's best, every parameter
    std::vector<SearchDimension> space;     ///< empty: a tuning written before spaces were recorded
    std::optional<CostCoefficients> model;  ///< none: no model could be fitted, or an older tuning
};

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

}  // namespace

Advice advise(const AdviseOptions& o) {
    if (o.method != "auto" && o.method != "category" && o.method != "model")
        throw InputError("--method: expected auto, category or model, got " + quoted_excerpt(o.method));
    if (o.tuning.empty() && !o.category.empty()) throw InputError("--category needs --tuning");
    if (o.tuning.empty() && o.exhaustive) throw InputError("--exhaustive needs --tuning");
    if (!std::filesystem::is_regular_file(o.scene)) throw InputError(o.scene + ": no such file");
    TuneCategory category;
    category.name = std::filesystem::path(o.scene).stem().string();
    SceneSpec spec;
    spec.name = category.name;
    spec.path = o.scene;
    spec.key = {{"advise", o.scene}};
    const bool csv = o.scene.size() >= 4 && o.scene.compare(o.scene.size() - 4, 4, ".csv") == 0;
    spec.source = csv ? SceneSpec::Source::import : SceneSpec::Source::recording;
    if (csv) spec.settings.frames = 10;
    category.scenes.push_back(spec);

    Advice advice;
    std::map<std::string, TunedStructure> tuned;
    std::string wanted = o.category;
    std::size_t budget = 30;
    std::uint64_t seed = 1;
    if (!o.tuning.empty()) {
        const json t = parse_json_document(read_text_file(o.tuning), o.tuning);
        if (wanted.empty()) {
            advice.chosen = choose_category(o.tuning, t, recording_of(spec));
            wanted = advice.chosen->category;
        }
        tuned = read_category(t, o.tuning, wanted);
        if (t.contains("budget") && t["budget"].is_number_unsigned() && t["budget"].get<std::size_t>() > 0)
            budget = std::min<std::size_t>(t["budget"].get<std::size_t>(), 10'000);
        if (t.contains("seed") && t["seed"].is_number_unsigned()) seed = t["seed"].get<std::uint64_t>();
    }
    try {
        check_warmup(o.warmup, recording_of(spec).frames.size());
    } catch (const InputError& e) {
        throw InputError(o.scene + ": " + e.what());
    }

    // Every structure's parameters and method are checked before the first measurement, so a bad
    // tuning file or an impossible --method fails at once, not after minutes of measuring.
    std::vector<std::pair<const StructureInfo*, json>> configured;  // structure, complete params
    for (const StructureInfo& info : structure_registry()) {
        auto it = tuned.find(info.name);
        if (it == tuned.end()) {
            configured.push_back({&info, info.complete(json::object(), info.name)});
            continue;
        }
        const TunedStructure& ts = it->second;
        configured.push_back({&info, info.complete(ts.params, o.tuning)});
        ParameterChoice pc;
        pc.structure = info.name;
        pc.space = ts.space;
        pc.category_searched = searched_of(ts.params, ts.space);
        const bool can_model = ts.model && !ts.space.empty();
        if (o.method == "model" && !can_model)
            throw InputError(o.tuning + ": category \"" + wanted + "\" holds no cost model and space for " + info.name +
                             " (tuned by an older rcbench, or too few configurations to fit one); use --method "
                             "category or tune again");
        if (o.exhaustive && ts.space.empty())
            throw InputError(o.tuning + ": category \"" + wanted + "\" records no search space for " + info.name +
                             " (tuned by an older rcbench); --exhaustive needs one: tune again");
        pc.method = o.method == "category" || !can_model ? "category" : "model";
        if (pc.method == "model") {
            pc.model = ts.model->model;
            pc.why = o.method == "model" ? "--method model"
                                         : "the tuning holds a cost model for " + info.name + " in category " + wanted +
                                               ", so this scene's own counters decide instead of the best of the "
                                               "category's scenes";
        } else {
            pc.why = o.method == "category"
                         ? "--method category"
                         : "the tuning holds no cost model for " + info.name + " in category " + wanted +
                               " (tuned by an older rcbench, or too few configurations to fit "
                               "one), so the category's parameters are used as they are";
        }
        pc.chosen_searched = pc.category_searched;
        advice.parameters.push_back(std::move(pc));
    }

    // The model method: the category's cost model on this scene's counters picks the candidates,
    // measurements on the scene decide among them and the category's own parameters.
    const bool verify = o.accuracy.needs_verification();
    for (ParameterChoice& pc : advice.parameters) {
        const TunedStructure& ts = tuned.at(pc.structure);
        std::size_t index = 0;
        while (configured[index].first->name != pc.structure) ++index;
        const StructureInfo& info = *configured[index].first;
        auto full_params = [&](const json& searched) {
            json p = ts.params;
            for (const auto& [k, v] : searched.items()) p[k] = v;
            return info.complete(p, o.tuning);
        };
        if (pc.method == "category") {
            pc.summary = pc.structure + ": " + searched_text(pc.category_searched) + ", category " + wanted +
                         "'s tuned parameters (" + pc.why + ").";
            continue;
        }
        if (o.progress) o.progress(pc.structure + " (cost model on the scene)");
        const CostCoefficients& model = *ts.model;
        std::vector<std::pair<json, ReplayCounts>> counted;  // every replay's counts
        const SearchResult r = search_levels(
            pc.space,
            [&](const json& p) {
                ReplayCounts counts;
                const double ms = predict_cost(model, category, pc.structure, p, o.warmup, &counts);
                counted.push_back({p, counts});
                return ms;
            },
            budget, seed, pc.category_searched);
        auto counts_of = [&](const json& p) {
            for (const auto& [q, c] : counted)
                if (same_point(p, q, pc.space)) return std::optional<ReplayCounts>(c);
            return std::optional<ReplayCounts>();
        };
        pc.replays = r.evaluations.size();
        pc.space_size = r.space_size;
        std::vector<std::size_t> order(r.evaluations.size());
        for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
        std::stable_sort(order.begin(), order.end(),
                         [&](std::size_t a, std::size_t b) { return r.evaluations[a].cost < r.evaluations[b].cost; });
        // The best predictions are measured, one per structure in effect: a configuration that
        // counts exactly as one measured already is the same structure and tells nothing new.
        const std::size_t to_measure = std::max<std::size_t>(1, o.verify_top);
        std::vector<std::optional<ReplayCounts>> measured_counts;
        for (std::size_t k = 0; k < order.size(); ++k) {
            ModelCandidate c{r.evaluations[order[k]].params, r.evaluations[order[k]].cost, std::nullopt, false};
            c.is_category = same_point(c.searched, pc.category_searched, pc.space);
            const std::optional<ReplayCounts> counts = counts_of(c.searched);
            const bool repeat =
                counts && std::find(measured_counts.begin(), measured_counts.end(), counts) != measured_counts.end();
            if (measured_counts.size() < to_measure && !repeat) {
                c.measured = measure(category, pc.structure, full_params(c.searched), o.warmup, o.repetitions, verify);
                measured_counts.push_back(counts);
            }
            pc.candidates.push_back(std::move(c));
        }
        // The category's parameters compete unless only the prediction decides (--verify-top 0).
        auto category_candidate = std::find_if(pc.candidates.begin(), pc.candidates.end(),
                                               [](const ModelCandidate& c) { return c.is_category; });
        if (o.verify_top > 0) {
            if (category_candidate == pc.candidates.end()) {
                pc.candidates.push_back({pc.category_searched, std::nullopt, std::nullopt, true});
                category_candidate = pc.candidates.end() - 1;
            }
            if (!category_candidate->measured) {
                category_candidate->measured =
                    measure(category, pc.structure, full_params(pc.category_searched), o.warmup, o.repetitions, verify);
                measured_counts.push_back(counts_of(pc.category_searched));
            }
        }
        // The model's error (held out, a few percent) can rank a neighbour of the best below it,
        // so a measured descent refines the verified best: one level up or down in one parameter
        // at a time (two where one finds nothing), moving to any faster configuration, until none
        // is or `refine` measurements are spent. A neighbour that counts like one measured already
        // is that structure again.
        std::size_t& refined = pc.refined;
        // Meeting the accuracy first, then the lower time per frame.
        auto faster = [&](const MeasuredCost& a, const MeasuredCost& b) {
            const bool ma = o.accuracy.met_by(a.accuracy), mb = o.accuracy.met_by(b.accuracy);
            return ma != mb ? ma : a.ms < b.ms;
        };
        std::optional<std::size_t> current;  // into pc.candidates: the fastest measured
        for (std::size_t k = 0; k < pc.candidates.size(); ++k)
            if (pc.candidates[k].measured &&
                (!current || faster(*pc.candidates[k].measured, *pc.candidates[*current].measured)))
                current = k;
        // Measures `q` unless it is a structure measured already; true when it is the fastest now.
        auto probe = [&](const json& q) {
            std::optional<ReplayCounts> counts = counts_of(q);
            std::optional<double> predicted;
            if (!counts) {
                ReplayCounts replayed;
                predicted = predict_cost(model, category, pc.structure, q, o.warmup, &replayed);
                counted.push_back({q, replayed});
                counts = replayed;
            }
            if (std::find(measured_counts.begin(), measured_counts.end(), counts) != measured_counts.end())
                return false;
            std::size_t k = 0;
            while (k < pc.candidates.size() && !same_point(pc.candidates[k].searched, q, pc.space)) ++k;
            if (k == pc.candidates.size())
                pc.candidates.push_back({q, predicted, std::nullopt, same_point(q, pc.category_searched, pc.space)});
            pc.candidates[k].measured =
                measure(category, pc.structure, full_params(q), o.warmup, o.repetitions, verify);
            measured_counts.push_back(counts);
            ++refined;
            if (!faster(*pc.candidates[k].measured, *pc.candidates[*current].measured)) return false;
            current = k;
            return true;
        };
        // Neighbours one level away first; where none is faster, two levels away, past a bump (a
        // map's walls can make a grid's cost rise and fall again along one parameter).
        auto step_from = [&](const json& from, std::ptrdiff_t stride) {
            for (const SearchDimension& d : pc.space) {
                if (!from.contains(d.name)) continue;
                const auto at = std::find(d.levels.begin(), d.levels.end(), from[d.name]);
                if (at == d.levels.end()) continue;
                for (const std::ptrdiff_t step : {stride, -stride}) {
                    const std::ptrdiff_t i = (at - d.levels.begin()) + step;
                    if (i < 0 || i >= std::ptrdiff_t(d.levels.size()) || refined == o.refine) continue;
                    json q = from;
                    q[d.name] = d.levels[std::size_t(i)];
                    if (probe(q)) return true;
                }
            }
            return false;
        };
        if (o.verify_top > 0 && current)
            while (refined < o.refine) {
                const json from = pc.candidates[*current].searched;
                if (!step_from(from, 1) && !step_from(from, 2)) break;
            }
        // Measured first, fastest (meeting the accuracy) first; then the rest by prediction.
        std::stable_sort(pc.candidates.begin(), pc.candidates.end(),
                         [&](const ModelCandidate& a, const ModelCandidate& b) {
                             if (a.measured.has_value() != b.measured.has_value()) return a.measured.has_value();
                             if (!a.measured)
                                 return a.predicted_ms.value_or(INFINITY) < b.predicted_ms.value_or(INFINITY);
                             return faster(*a.measured, *b.measured);
                         });
        pc.chosen_searched = pc.candidates.front().searched;
        configured[index].second = full_params(pc.chosen_searched);

        std::string measured_text;
        for (const ModelCandidate& c : pc.candidates) {
            if (!c.measured) continue;
            measured_text += std::string(measured_text.empty() ? "" : ", ") + searched_text(c.searched) + " " +
                             ms_text(c.measured->ms) + " ms" +
                             (c.predicted_ms ? " (predicted " + ms_text(*c.predicted_ms) + ")" : "") +
                             (c.is_category ? " [category's]" : "");
        }
        pc.summary = pc.structure + ": " + searched_text(pc.chosen_searched) + " by the cost model of category " +
                     wanted + ", " + pc.model + ", on this scene's counters (" + pc.why +
                     "): " + std::to_string(pc.replays) + " of " + std::to_string(pc.space_size) +
                     " configurations replayed (" + r.algorithm + "); measured " + measured_text +
                     (pc.refined > 0 ? "; " + std::to_string(pc.refined) + " of them by the measured descent" : "") +
                     (o.verify_top > 0 ? "; the fastest measured is advised."
                                       : "; the predicted best is advised (--verify-top 0).");
    }

    // Every structure measured at its parameters (the model method's choice measured already).
    std::vector<AdviceRow>& rows = advice.rows;
    std::vector<json> params;
    for (const auto& [info, p] : configured) {
        const bool is_tuned = tuned.count(info->name) != 0;
        params.push_back(p);
        rows.push_back({info->name, p.dump(), {}, is_tuned});
        // Inexact answers allowed: the same configuration at the other query levels competes too
        // (a tuned level is kept as the tuning chose it).
        if (o.accuracy.allows_inexact() && query_level_of(p) == QueryLevel::boxes)
            for (const char* level : {"candidates", "shapes"}) {
                json q = p;
                q["query"] = level;
                params.push_back(info->complete(q, "advise"));
                rows.push_back({info->name, params.back().dump(), {}, is_tuned});
            }
    }
    std::map<std::string, MeasuredCost> already;  // the model method's measured choices, by params
    for (const ParameterChoice& pc : advice.parameters)
        for (const ModelCandidate& c : pc.candidates)
            if (c.measured && same_point(c.searched, pc.chosen_searched, pc.space)) {
                for (const auto& [info, p] : configured)
                    if (info->name == pc.structure) already[info->name + p.dump()] = *c.measured;
            }
    for (std::size_t i = 0; i < rows.size(); ++i) {
        auto it = already.find(rows[i].structure + rows[i].params);
        if (it != already.end()) {
            rows[i].cost = it->second;
            continue;
        }
        if (o.progress) o.progress(rows[i].structure);
        rows[i].cost = measure(category, rows[i].structure, params[i], o.warmup, o.repetitions, verify);
    }
    advice.recommended = rank_advice(rows, o.accuracy);

    if (o.exhaustive)
        for (const ParameterChoice& pc : advice.parameters) {
            if (o.progress) o.progress(pc.structure + " (every configuration)");
            const TunedStructure& ts = tuned.at(pc.structure);
            const StructureInfo& info = find_structure(pc.structure);
            ExhaustiveAdvice ex;
            ex.structure = pc.structure;
            ex.advised_searched = pc.chosen_searched;
            ex.category_searched = pc.category_searched;
            ex.best_ms = INFINITY;
            const std::vector<json> all = enumerate_space(pc.space);
            ex.configurations = all.size();
            std::vector<json> full_params;
            for (const json& p : all) {
                json full = ts.params;
                for (const auto& [k, v] : p.items()) full[k] = v;
                full_params.push_back(info.complete(full, o.tuning));
            }
            const std::vector<MeasuredCost> costs =
                measure_interleaved(category, pc.structure, full_params, o.warmup, o.repetitions, verify);
            for (std::size_t i = 0; i < all.size(); ++i) {
                const json& p = all[i];
                // Configurations that fail the accuracy are priced out, as in tune --exhaustive.
                const double ms = constrained_cost(costs[i], o.accuracy);
                if (ms < ex.best_ms) ex.best_ms = ms, ex.best_searched = p;
                if (same_point(p, pc.chosen_searched, pc.space)) ex.advised_ms = ms;
                if (same_point(p, pc.category_searched, pc.space)) ex.category_ms = ms;
            }
            advice.exhaustive.push_back(ex);
        }
    return advice;
}

std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy) {
    std::stable_sort(rows.begin(), rows.end(),
                     [](const AdviceRow& a, const AdviceRow& b) { return a.cost.ms < b.cost.ms; });
    std::optional<std::size_t> best;
    for (std::size_t i = 0; i < rows.size(); ++i) {
        rows[i].meets = accuracy.met_by(rows[i].cost.accuracy);
        if (rows[i].meets && !best) best = i;
    }
    return best;
}

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
    if (a.chosen)
        j["category"] = {{"name", a.chosen->category},
                         {"distance", a.chosen->match.distance},
                         {"explanation", a.chosen->explanation},
                         {"features", a.chosen->features.to_json()}};
    else if (!o.category.empty())
        j["category"] = {{"name", o.category}, {"explanation", "--category"}};
    for (const ParameterChoice& pc : a.parameters) {
        json pj = {{"structure", pc.structure},
                   {"method", pc.method},
                   {"why", pc.why},
                   {"category_params", pc.category_searched},
                   {"params", pc.chosen_searched},
                   {"summary", pc.summary},
                   {"candidates", json::array()}};
        if (pc.method == "model")
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
        json rj = {{"structure", r.structure},
                   {"params", json::parse(r.params)},
                   {"tuned", r.tuned},
                   {"meets", r.meets},
                   {"cost", cost_json(r.cost)}};
        j["rows"].push_back(rj);
    }
    if (a.recommended)
        j["recommended"] = {{"structure", a.rows[*a.recommended].structure},
                            {"params", json::parse(a.rows[*a.recommended].params)}};
    for (const ExhaustiveAdvice& e : a.exhaustive)
        j["exhaustive"].push_back({{"structure", e.structure},
                                   {"configurations", e.configurations},
                                   {"best_params", e.best_searched},
                                   {"best_ms", e.best_ms},
                                   {"advised_params", e.advised_searched},
                                   {"advised_ms", e.advised_ms},
                                   {"advised_gap", e.advised_gap()},
                                   {"category_params", e.category_searched},
                                   {"category_ms", e.category_ms},
                                   {"category_gap", e.category_gap()}});
    return j;
}

}  // namespace rcb

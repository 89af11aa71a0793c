#include "tuner/run_tuning.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>

#include "analysis/charts.h"
#include "analysis/cost_model.h"
#include "core/base/number_text.h"
#include "core/base/output_file.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "runner/build_info.h"
#include "runner/results_writer.h"
#include "runner/store.h"
#include "tuner/search_baselines.h"

namespace rcb {

std::string searched_parameters(const TuneSpec& spec, const Candidate& c) {
    std::string out;
    for (const SearchDimension& d : spec.space.at(c.structure))
        out += (out.empty() ? "" : " ") + d.name + "=" +
               (c.params[d.name].is_string() ? c.params[d.name].get<std::string>() : c.params[d.name].dump());
    return out;
}

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string cost_text(const MeasuredCost& c) { return fixed(c.ms, 4) + " ± " + fixed(c.mad, 4); }

json candidate_json(const Candidate& c) {
    json j = {{"structure", c.structure}, {"params", c.params}, {"default", c.is_default}};
    if (c.predicted_ms) j["predicted_ms"] = *c.predicted_ms;
    if (c.measured)
        j["measured"] = {{"ms", c.measured->ms},
                         {"mad", c.measured->mad},
                         {"update_ms", c.measured->update_ms},
                         {"raycast_ms", c.measured->raycast_ms},
                         {"memory_bytes", c.measured->memory_bytes}};
    if (c.measured && c.measured->accuracy.verified)
        j["measured"]["accuracy"] = {{"precision", c.measured->accuracy.precision},
                                     {"recall", c.measured->accuracy.recall},
                                     {"mismatches", c.measured->accuracy.mismatches}};
    return j;
}

std::string convergence_chart(const CategoryTuning& ct, const TuneSpec& spec) {
    Chart c;
    c.title = "Search convergence on " + ct.category + " (" + spec.mode + ")";
    c.x_label = "evaluation";
    c.y_label = spec.mode == "measured" ? "best measured cost so far (ms per frame)"
                                        : "best predicted cost so far (ms per frame)";
    for (const StructureTuning& st : ct.structures) {
        Series s{st.structure, {}, {}, {}, true, structure_simplicity(st.structure) + 1};
        double best = INFINITY;
        for (std::size_t i = 0; i < st.search.evaluations.size(); ++i) {
            best = std::min(best, st.search.evaluations[i].cost);
            s.x.push_back(double(i + 1));
            s.y.push_back(best);
        }
        c.series.push_back(s);
    }
    c.reading = "Best cost found after each distinct evaluation.";
    return render_svg(c);
}

void store_tuning(ResultStore& store, const TuneSpec& spec, const CategoryTuning& ct) {
    std::vector<StoredTuning> rows;
    for (const StructureTuning& st : ct.structures) {
        const Candidate& best = st.candidates[st.best_candidate];
        const Candidate* def = nullptr;
        for (const Candidate& c : st.candidates)
            if (c.is_default) def = &c;
        StoredTuning r;
        r.structure = st.structure, r.mode = st.mode, r.algorithm = st.search.algorithm;
        r.git_commit = kGitCommit, r.spec = spec.content;
        r.evaluations = std::int64_t(st.search.evaluations.size()), r.measurements = std::int64_t(st.measurements);
        r.seconds = st.seconds, r.stop_reason = st.search.stop_reason, r.on_bound = json(st.search.on_bound).dump();
        r.best_params = best.params.dump();
        r.best_measured_ms = best.measured->ms, r.best_measured_mad = best.measured->mad;
        r.best_predicted_ms = best.predicted_ms;
        r.default_params = def ? def->params.dump() : std::string("{}");
        r.default_measured_ms = def ? std::optional<double>(def->measured->ms) : std::nullopt;
        r.chosen = ct.chosen.structure == st.structure && ct.chosen.params == best.params;
        r.accuracy = spec.accuracy.text();
        for (const auto& e : st.search.evaluations) r.evaluation.push_back({e.params.dump(), e.cost});
        r.evaluation_kind = st.mode == "measured" ? "measured" : "predicted";
        rows.push_back(std::move(r));
    }
    write_tuning(store.db(), spec.name, ct.category, rows);
}

}  // namespace

SceneClustering categorize_tuning_scenes(TuneSpec& spec, bool derive) {
    std::vector<SceneSpec> scenes;
    std::vector<SceneFeatures> features;
    std::vector<std::string> names;
    std::vector<std::vector<std::size_t>> members;
    std::map<std::string, std::size_t> index;  // scene key → its place among the distinct scenes
    for (const TuneCategory& c : spec.categories) {
        names.push_back(c.name);
        members.emplace_back();
        for (const SceneSpec& s : c.scenes) {
            const std::string key = s.key.dump();
            if (!index.count(key)) {
                index[key] = scenes.size();
                scenes.push_back(s);
                features.push_back(compute_scene_features(recording_of(s)));
            }
            members.back().push_back(index[key]);
        }
    }
    if (!derive) return group_scenes(features, names, members);
    std::vector<std::string> fixed_categories;
    for (const SceneSpec& s : scenes) fixed_categories.push_back(scene_category(s.key.dump()));
    const SceneClustering clustering = cluster_scenes(features, fixed_categories, spec.seed);
    spec.categories.clear();
    for (const DerivedCategory& d : clustering.categories) {
        TuneCategory c;
        c.name = d.name;
        for (std::size_t i : d.members) c.scenes.push_back(scenes[i]);
        spec.categories.push_back(c);
    }
    return clustering;
}

std::vector<SurfaceReplay> replay_search_on_surface(const std::vector<SearchDimension>& dims,
                                                    const std::map<std::string, double>& surface, std::size_t budget,
                                                    std::uint64_t first_seed, std::size_t seeds,
                                                    const nlohmann::json& start) {
    std::vector<SurfaceReplay> out;
    for (std::uint64_t seed = first_seed; seed < first_seed + seeds; ++seed) {
        const SearchResult r = search_levels(
            dims, [&](const nlohmann::json& p) { return surface.at(p.dump()); }, budget, seed, start);
        out.push_back({seed, r.evaluations.size(), r.evaluations[r.best].cost, r.evaluations[r.best].params});
    }
    return out;
}

namespace {

/// The output files of a tuning, checked before any work (InputError naming the option).
struct TuningOutputs {
    fs::path md, json;
};

TuningOutputs check_outputs(const TuneSpec& spec, const TuneOptions& o) {
    const TuningOutputs out{fs::path(o.out_dir) / ("tuning-" + spec.name + ".md"),
                            fs::path(o.out_dir) / ("tuning-" + spec.name + ".json")};
    std::vector<std::string> inputs{o.file, o.db};
    for (const TuneCategory& c : spec.categories)
        for (const SceneSpec& s : c.scenes) inputs.push_back(s.path);
    check_output_path(o.db, {o.file}, "--db");
    check_output_path(out.md.string(), inputs, "--out-dir");
    check_output_path(out.json.string(), inputs, "--out-dir");
    return out;
}

/// The report's opening: the settings, and the derived categories' members.
std::string header_md(const TuneSpec& spec, const SceneClustering& clustering, bool derived) {
    std::ostringstream md;
    md << "# Tuning " << spec.name << "\n\n"
       << spec.description << "\n\nMode: " << spec.mode << "; budget " << spec.budget
       << " distinct evaluations per structure and category; seed " << spec.seed << "; " << spec.repetitions
       << " repetitions per measurement; accuracy " << spec.accuracy.text() << "; commit " << kGitCommit
       << ". Costs are per frame: update + the frame's rays (thesis eq. 5.5), median over frames and repetitions ± "
          "MAD, "
          "averaged over the category's scenes. The thesis does not publish its grid settings, so they cannot be "
          "compared here.\n";
    if (derived) {
        md << "\nCategories derived from the scenes' features (" << clustering.rule << "):\n\n"
           << "| category | scenes | nearest fixed category |\n|---|---|---|\n";
        for (std::size_t i = 0; i < spec.categories.size(); ++i) {
            std::string list;
            for (const SceneSpec& s : spec.categories[i].scenes) list += (list.empty() ? "" : ", ") + s.name;
            md << "| " << spec.categories[i].name << " | " << list << " | " << clustering.categories[i].nearest_fixed
               << " |\n";
        }
    }
    return md.str();
}

json header_json(const TuneSpec& spec, const SceneClustering& clustering, bool derived) {
    json out = {{"name", spec.name},
                {"mode", spec.mode},
                {"budget", spec.budget},
                {"seed", spec.seed},
                {"git_commit", kGitCommit},
                {"categories", json::array()},
                {"accuracy", spec.accuracy.text()}};
    // What `advise` needs to map an unseen scene to one of these categories.
    out["scene_categories"] = clustering.to_json();
    out["scene_categories"]["derived"] = derived;
    return out;
}

std::string candidate_note(const TuneSpec& spec, const StructureTuning& st, std::size_t i) {
    const Candidate& c = st.candidates[i];
    std::string note = c.is_default ? "defaults" : "";
    if (i == st.best_candidate) note += std::string(note.empty() ? "" : ", ") + "best measured";
    if (c.measured->accuracy.verified)
        note += std::string(note.empty() ? "" : ", ") + "precision " + fixed(c.measured->accuracy.precision, 3) +
                ", recall " + fixed(c.measured->accuracy.recall, 3) +
                (spec.accuracy.met_by(c.measured->accuracy) ? "" : " (fails " + spec.accuracy.text() + ")");
    return note;
}

/// One category's section: the recommendation, every measured candidate, and each search.
std::string category_md(const TuneSpec& spec, const CategoryTuning& ct) {
    std::ostringstream md;
    md << "\n## " << ct.category << "\n\nRecommended: **" << ct.chosen.structure << " "
       << searched_parameters(spec, ct.chosen) << "** at " << cost_text(*ct.chosen.measured) << " ms per frame";
    if (!ct.rule_note.empty()) md << " (" << ct.rule_note << ")";
    md << ".\n\n| structure | configuration | predicted ms | measured ms | update ms | ray cast ms | memory B | "
          "note |\n|---|---|---|---|---|---|---|---|\n";
    for (const StructureTuning& st : ct.structures)
        for (std::size_t i = 0; i < st.candidates.size(); ++i) {
            const Candidate& c = st.candidates[i];
            md << "| " << c.structure << " | " << searched_parameters(spec, c) << " | "
               << (c.predicted_ms ? fixed(*c.predicted_ms, 4) : "-") << " | " << cost_text(*c.measured) << " | "
               << fixed(c.measured->update_ms, 4) << " | " << fixed(c.measured->raycast_ms, 4) << " | "
               << fixed(c.measured->memory_bytes, 0) << " | " << candidate_note(spec, st, i) << " |\n";
        }
    md << "\n| structure | search | evaluations (space) | measurements | seconds | stopped | best at the edge of "
          "its range |\n|---|---|---|---|---|---|---|\n";
    for (const StructureTuning& st : ct.structures) {
        std::string edge;
        for (const std::string& b : st.search.on_bound) edge += (edge.empty() ? "" : ", ") + b;
        md << "| " << st.structure << " | " << st.search.algorithm
           << (st.prediction_model.empty() ? "" : "; prediction: " + st.prediction_model) << " | "
           << st.search.evaluations.size() << " (" << st.search.space_size << ") | " << st.measurements << " | "
           << fixed(st.seconds, 1) << " | " << st.search.stop_reason << " | "
           << (edge.empty() ? "-" : edge + ": consider widening its range") << " |\n";
    }
    return md.str();
}

json category_json(const TuneSpec& spec, const CategoryTuning& ct) {
    json cj = {{"category", ct.category},
               {"chosen", candidate_json(ct.chosen)},
               {"fastest", candidate_json(ct.fastest)},
               {"rule_note", ct.rule_note},
               {"structures", json::array()}};
    for (const StructureTuning& st : ct.structures) {
        json sj = {{"structure", st.structure},
                   {"algorithm", st.search.algorithm},
                   {"stop_reason", st.search.stop_reason},
                   {"on_bound", st.search.on_bound},
                   {"evaluations", st.search.evaluations.size()},
                   {"space_size", st.search.space_size},
                   {"measurements", st.measurements},
                   {"seconds", st.seconds},
                   {"prediction_model", st.prediction_model},
                   {"best", candidate_json(st.candidates[st.best_candidate])},
                   {"candidates", json::array()}};
        for (const Candidate& c : st.candidates) sj["candidates"].push_back(candidate_json(c));
        // What advise needs to choose this structure's parameters for an unseen scene: the
        // space searched here and the category's cost model, applied to that scene's counters.
        sj["space"] = json::array();  // in the search's order of dimensions
        for (const SearchDimension& d : spec.space.at(st.structure))
            sj["space"].push_back({{"name", d.name}, {"levels", d.levels}});
        if (st.cost_model) sj["cost_model"] = st.cost_model->to_json();
        // The update's prices: what lets advise predict an unseen scene's update, not time it.
        if (st.update_model) sj["update_model"] = st.update_model->to_json();
        cj["structures"].push_back(sj);
    }
    return cj;
}

/// One structure's exhaustive check (--exhaustive): every configuration measured (the table every
/// method chooses on), the search replayed on that surface, and the prediction's ranking of it;
/// then every configuration measured again (the scores, search_baselines.h), on which every
/// choice, the tuner's own included, is priced.
struct ExhaustiveCheck {
    std::string structure;
    std::size_t configurations = 0, evaluations = 0;
    double best_table_ms = INFINITY;  ///< the table's fastest configuration that meets the accuracy
    double best_ms = NAN;             ///< that configuration re-measured
    json best_params;
    double tuned_ms = NAN;  ///< the tuner's best, re-measured (NaN: not a configuration of the space)
    std::vector<SurfaceReplay> replays;
    std::string model;  ///< the prediction's model
    double spearman = 0;
    json surface = json::array();  ///< every configuration: params, ms, meets, predicted_ms
    BudgetComparison comparison;   ///< the tuner against random search and descent at one budget
};

/// The equal-budget comparison's budget: a tenth of the structures in effect of a space.
constexpr double kComparisonBudgetShare = 0.1;

ExhaustiveCheck check_exhaustively(const TuneSpec& spec, const TuneCategory& category, const StructureTuning& st,
                                   MachinePriors& priors) {
    const std::vector<SearchDimension>& dims = spec.space.at(st.structure);
    const json defaults = find_structure(st.structure).defaults();
    ExhaustiveCheck ex;
    ex.structure = st.structure;
    ex.evaluations = st.search.evaluations.size();
    const auto all = enumerate_space(dims);
    ex.configurations = all.size();
    std::vector<json> full_params;
    for (const json& p : all) {
        json full = defaults;
        for (const auto& [k, v] : p.items()) full[k] = v;
        full_params.push_back(full);
    }
    std::vector<std::vector<FrameObservation>> observed;  // each configuration's frames, for the ranked refits
    const std::vector<MeasuredCost> costs =
        measure_interleaved(category, st.structure, full_params, spec.warmup_frames, spec.repetitions,
                            spec.accuracy.needs_verification(), &observed);
    // The scoring pass: the space measured again after the table, which alone every method (and
    // the optimum) is chosen from; every choice is priced on this one.
    std::vector<double> scores;
    for (const MeasuredCost& m : measure_interleaved(category, st.structure, full_params, spec.warmup_frames,
                                                     spec.repetitions, spec.accuracy.needs_verification()))
        scores.push_back(constrained_cost(m, spec.accuracy));
    std::map<std::string, double> rescored;  // searched params → their score
    std::map<std::string, double> surface;   // searched params → measured ms
    std::vector<double> measured, constrained;
    for (std::size_t i = 0; i < all.size(); ++i) {
        const json& p = all[i];
        const MeasuredCost& m = costs[i];
        // The surface the search sees: configurations failing the accuracy priced out.
        const double ms = constrained_cost(m, spec.accuracy);
        surface[p.dump()] = ms;
        constrained.push_back(ms);
        measured.push_back(m.ms);  // the prediction ranks times, not the accuracy
        rescored[p.dump()] = scores[i];
        ex.surface.push_back(
            {{"params", p}, {"ms", m.ms}, {"rescored_ms", scores[i]}, {"meets", spec.accuracy.met_by(m.accuracy)}});
        if (spec.accuracy.met_by(m.accuracy) && ms < ex.best_table_ms)
            ex.best_table_ms = ms, ex.best_params = p, ex.best_ms = scores[i];
    }
    json tuned = json::object();  // the tuner's choice, as searched parameters
    for (const SearchDimension& d : dims) tuned[d.name] = st.candidates[st.best_candidate].params[d.name];
    if (rescored.count(tuned.dump())) ex.tuned_ms = rescored.at(tuned.dump());
    // The search itself, replayed on the measured surface with five seeds: its gap to the
    // optimum separated from the noise of measuring again.
    json defaults_searched = json::object();
    for (const SearchDimension& d : dims) defaults_searched[d.name] = defaults[d.name];
    ex.replays = replay_search_on_surface(dims, surface, spec.budget, spec.seed, 5, defaults_searched);
    for (SurfaceReplay& r : ex.replays) r.scored_ms = rescored.at(r.best_params.dump());
    // How well the predicted mode ranks the space: Spearman of prediction against measurement.
    // The predicted modes priced their search with the calibration's coefficients (cost_model);
    // the measured mode calibrates a prediction here.
    CostCoefficients coefficients;
    ex.model = st.prediction_model;
    std::size_t model_timed = st.prediction_measurements;
    if (st.predict && st.cost_model) {
        coefficients = *st.cost_model;
    } else {
        Predictor p = calibrate_predictor(spec, category, st.structure, &priors);
        coefficients = p.coefficients, ex.model = p.model, model_timed = p.measurements;
    }
    // The space is replayed once: the ranked method's replays where the tuning ran it (the same
    // space, in its order), else one replay per configuration here.
    const bool replayed = st.space_replays.size() == all.size();
    std::size_t next = 0;
    const SpaceSurvey survey = survey_space(all, coefficients, [&](const json& p) {
        return replayed ? st.space_replays[next++] : counting_replay(category, st.structure, p, spec.warmup_frames);
    });
    for (std::size_t i = 0; i < all.size(); ++i) ex.surface[i]["predicted_ms"] = survey.predicted[i];
    ex.spearman = spearman(survey.predicted, measured);
    // The ranked method as the measured mode runs it: from the micro-scene calibration alone,
    // refitted on the frames of what it has timed, here read from the exhaustive measurements.
    RankedInputs ranked;
    const std::optional<CostCoefficients> prior = prior_coefficients(&priors, st.structure);
    if (prior && all.size() <= kRankedSpaceLimit) {
        for (std::size_t i = 0; i < all.size(); ++i) {
            ranked.predicted.push_back(replay_cost(*prior, survey.replays[i]));
            ex.surface[i]["prior_predicted_ms"] = ranked.predicted.back();
        }
        ranked.replays = all.size();
        ranked.refit = [&](const std::vector<std::size_t>& timed) {
            std::vector<FrameObservation> frames;
            for (std::size_t i : timed) frames.insert(frames.end(), observed[i].begin(), observed[i].end());
            return refit_predictions(frames, timed.size(), survey.replays, &priors, st.structure);
        };
    }
    ex.comparison =
        compare_at_equal_budget(dims, all, constrained, survey.class_of, defaults_searched, kComparisonBudgetShare,
                                spec.seed, 5, survey.predicted, model_timed, prior ? &ranked : nullptr, scores);
    return ex;
}

std::string exhaustive_md(const TuneSpec& spec, const std::vector<ExhaustiveCheck>& checks) {
    std::ostringstream md;
    md << "\nExhaustive check (every configuration measured twice: the table every method chooses on, whose "
          "best is the optimum, then again after it, the scores every choice is priced on; gap = the choice's "
          "score / the optimum's score − 1):\n\n| structure | configurations | best (table ms, re-measured ms) | "
          "tuner's best re-measured | gap | tuner's evaluations |\n|---|---|---|---|---|---|\n";
    for (const ExhaustiveCheck& ex : checks)
        md << "| " << ex.structure << " | " << ex.configurations << " | " << ex.best_params.dump() << " ("
           << fixed(ex.best_table_ms, 4) << ", " << fixed(ex.best_ms, 4) << ") | " << fixed(ex.tuned_ms, 4) << " | "
           << fixed(100 * (ex.tuned_ms / ex.best_ms - 1), 1) << "% | " << ex.evaluations << " ("
           << fixed(100.0 * double(ex.evaluations) / double(ex.configurations), 0) << "%) |\n";
    md << "\nThe search replayed on the exhaustively measured surface (budget " << spec.budget
       << ", starting from the defaults), five seeds; and the predicted mode's ranking of every "
          "configuration:\n\n| structure | seed | evaluations (of the space) | best found (table ms) | gap to the "
          "optimum (re-measured) |\n|---|---|---|---|---|\n";
    for (const ExhaustiveCheck& ex : checks) {
        for (const SurfaceReplay& r : ex.replays)
            md << "| " << ex.structure << " | " << r.seed << " | " << r.evaluations << " ("
               << fixed(100.0 * double(r.evaluations) / double(ex.configurations), 0) << "%) | " << fixed(r.best_ms, 4)
               << " " << r.best_params.dump() << " | " << fixed(100 * (r.scored_ms / ex.best_ms - 1), 1) << "% |\n";
        md << "| " << ex.structure << " | prediction (" << ex.model << ") | " << ex.configurations
           << " predicted | Spearman " << fixed(ex.spearman, 3) << " against measured | |\n";
    }
    md << "\nAt equal budgets, every method choosing on the table: configurations that count alike in a "
          "replay merged into one structure in effect (its cost the median of theirs); each method may "
          "time a tenth of those (the budget: timed configurations of the space, everything counted) and "
          "has the replays of the whole space (every configuration replayed once: the classes all of them "
          "draw and walk by, the ranking of the ranked method); regret = the choice's re-measured cost / "
          "the table optimum's re-measured cost − 1 (below 0: it beat the optimum on the re-measurement). "
          "The tuner is the ranked method (every configuration replayed, its rays counted and its update "
          "timed, and ranked by the cost model from the micro-scene calibration alone, the best-ranked timed, the "
          "model refitted on them; timed / "
          "replayed in brackets), or where no model exists the search (pattern search + DIRECT, median of "
          "five seeds). Random: the exact expectation; descent: advise's model-free descent from the "
          "defaults. The last column is the cost model's lowest-predicted configuration, its model "
          "calibrated on the configurations in brackets, timed beyond the budget:\n\n"
          "| structure | configurations | in effect | budget | tuner: ranked (timed / replayed) | search | "
          "random | descent | model alone (timed) |\n|---|---|---|---|---|---|---|---|---|\n";
    for (const ExhaustiveCheck& ex : checks) {
        const BudgetComparison& c = ex.comparison;
        md << "| " << ex.structure << " | " << c.configurations << " | " << c.classes << " | " << c.budget << " | "
           << (std::isnan(c.ranked_regret) ? std::string("- (no model: the search)")
                                           : fixed(100 * c.ranked_regret, 1) + "% (" + std::to_string(c.ranked_timed) +
                                                 " / " + std::to_string(c.ranked_replays) + ")")
           << " | " << fixed(100 * c.tuner_regret, 1) << "% | " << fixed(100 * c.random_regret, 1) << "% | "
           << fixed(100 * c.descent_regret, 1) << "% | "
           << (std::isnan(c.model_regret)
                   ? std::string("-")
                   : fixed(100 * c.model_regret, 1) + "% (" + std::to_string(c.model_timed) + ")")
           << " |\n";
    }
    return md.str();
}

json comparison_json(const BudgetComparison& c) {
    return {{"configurations", c.configurations},
            {"in_effect", c.classes},
            {"budget", c.budget},
            {"optimum_table_ms", c.optimum_table},
            {"optimum_ms", c.optimum},
            {"timed", c.budget},
            {"replays", c.configurations},
            {"tuner_regrets", c.tuner_regrets},
            {"tuner_regret", c.tuner_regret},
            {"random_regret", c.random_regret},
            {"descent_regret", c.descent_regret},
            {"model_regret", std::isnan(c.model_regret) ? json(nullptr) : json(c.model_regret)},
            {"model_timed", c.model_timed},
            {"ranked_regret", std::isnan(c.ranked_regret) ? json(nullptr) : json(c.ranked_regret)},
            {"ranked_unrefitted_regret",
             std::isnan(c.ranked_unrefitted_regret) ? json(nullptr) : json(c.ranked_unrefitted_regret)},
            {"ranked_timed", c.ranked_timed},
            {"ranked_replays", c.ranked_replays},
            {"ranked_refits", c.ranked_refits},
            {"tuner_is", std::isnan(c.ranked_regret) ? "search" : "ranked"}};
}

/// The tuning's problems (category × structure) over all categories, at equal budgets.
std::string suite_md(const SuiteSummary& s) {
    std::ostringstream md;
    md << "\n## Every problem at equal budgets\n\n"
       << s.problems << " problems (category × structure), each method timing a tenth of the structures in effect "
       << "(median " << fixed(100 * s.median_budget_share, 0)
       << "%), every timed configuration of the space counted:\n\n| method | regret median | regret p90 | "
          "below random's regret |\n|---|---|---|---|\n"
       << "| the tuner: ranked by the cost model (" << s.ranked_problems << " problems, median "
       << fixed(s.median_replays, 0) << " replays: rays counted, not timed; the update timed), else the search | "
       << fixed(100 * s.running_median, 1) << "% | " << fixed(100 * s.running_p90, 1) << "% | "
       << fixed(100 * s.running_beats_random, 0) << "% |\n"
       << "| search alone (pattern + DIRECT) | " << fixed(100 * s.tuner_median, 1) << "% | "
       << fixed(100 * s.tuner_p90, 1) << "% | " << fixed(100 * s.beats_random, 0) << "% |\n"
       << "| random search | " << fixed(100 * s.random_median, 1) << "% | " << fixed(100 * s.random_p90, 1) << "% | |\n"
       << "| model-free descent | " << fixed(100 * s.descent_median, 1) << "% | " << fixed(100 * s.descent_p90, 1)
       << "% | |\n";
    if (s.model_problems > 0)
        md << "| cost model alone (timed: its calibration, beyond the budget) | " << fixed(100 * s.model_median, 1)
           << "% | " << fixed(100 * s.model_p90, 1) << "% | |\n";
    md << "\nThe tuner is at or below the descent's regret in " << fixed(100 * s.running_matches_descent, 0)
       << "% of the problems (the search alone in " << fixed(100 * s.matches_descent, 0) << "%).\n";
    return md.str();
}

json suite_json(const SuiteSummary& s) {
    return {{"problems", s.problems},
            {"median_budget_share", s.median_budget_share},
            {"tuner",
             {{"median", s.running_median},
              {"p90", s.running_p90},
              {"beats_random", s.running_beats_random},
              {"matches_descent", s.running_matches_descent},
              {"ranked_problems", s.ranked_problems},
              {"median_replays", s.median_replays}}},
            {"search",
             {{"median", s.tuner_median},
              {"p90", s.tuner_p90},
              {"beats_random", s.beats_random},
              {"matches_descent", s.matches_descent}}},
            {"random", {{"median", s.random_median}, {"p90", s.random_p90}}},
            {"descent", {{"median", s.descent_median}, {"p90", s.descent_p90}}},
            {"model", s.model_problems
                          ? json{{"median", s.model_median}, {"p90", s.model_p90}, {"problems", s.model_problems}}
                          : json(nullptr)}};
}

json exhaustive_json(const std::vector<ExhaustiveCheck>& checks) {
    json out = json::array();
    for (const ExhaustiveCheck& ex : checks) {
        json seeds = json::array();
        for (const SurfaceReplay& r : ex.replays)
            seeds.push_back({{"seed", r.seed},
                             {"evaluations", r.evaluations},
                             {"best_ms", r.best_ms},
                             {"best_params", r.best_params},
                             {"scored_ms", r.scored_ms},
                             {"gap", r.scored_ms / ex.best_ms - 1}});
        out.push_back({{"structure", ex.structure},
                       {"configurations", ex.configurations},
                       {"best_table_ms", ex.best_table_ms},
                       {"best_ms", ex.best_ms},
                       {"best_params", ex.best_params},
                       {"tuned_ms", ex.tuned_ms},
                       {"evaluations", ex.evaluations},
                       {"search_on_measured_surface", seeds},
                       {"prediction_model", ex.model},
                       {"prediction_spearman", ex.spearman},
                       {"equal_budget", comparison_json(ex.comparison)},
                       {"surface", ex.surface}});
    }
    return out;
}

/// The report and its JSON as they stand, with the equal-budget summary over `problems` so far.
void write_report(const TuningOutputs& files, std::string md, json out, const std::vector<BudgetComparison>* problems) {
    if (problems) {
        const SuiteSummary summary = summarize_suite(*problems);
        md += suite_md(summary);
        out["equal_budget"] = suite_json(summary);
    }
    write_file_atomically(files.md.string(), md);
    write_file_atomically(files.json.string(), out.dump(2) + '\n');
}

}  // namespace

TuneOutcome run_tuning(const TuneSpec& file_spec, const TuneOptions& o) {
    TuneSpec spec = file_spec;
    const TuningOutputs files = check_outputs(spec, o);
    ResultStore store(o.db);
    TuneOutcome outcome;
    outcome.scene_categories = categorize_tuning_scenes(spec, o.derive_categories);
    std::string md = header_md(spec, outcome.scene_categories, o.derive_categories);
    json out = header_json(spec, outcome.scene_categories, o.derive_categories);
    // The machine's calibration of a structure, measured once if any category's fit needs it.
    MachinePriors priors;
    std::vector<BudgetComparison> problems;
    for (const TuneCategory& category : spec.categories) {
        if (o.progress) o.progress(category.name);
        const CategoryTuning ct = tune_category(spec, category, &priors);
        store_tuning(store, spec, ct);
        md += category_md(spec, ct);
        json cj = category_json(spec, ct);
        if (o.exhaustive) {
            std::vector<ExhaustiveCheck> checks;
            for (const StructureTuning& st : ct.structures)
                checks.push_back(check_exhaustively(spec, category, st, priors));
            md += exhaustive_md(spec, checks);
            cj["exhaustive"] = exhaustive_json(checks);
            for (const ExhaustiveCheck& ex : checks) problems.push_back(ex.comparison);
        }
        const std::string svg_name = "tuning-" + spec.name + "-" + ct.category + ".svg";
        write_file_atomically((fs::path(o.out_dir) / svg_name).string(), convergence_chart(ct, spec));
        md += "\n![convergence](" + svg_name + ")\n";
        out["categories"].push_back(cj);
        outcome.categories.push_back(ct);
        // Written after every category, so a long tuning stopped part-way keeps what it measured.
        write_report(files, md, out, o.exhaustive ? &problems : nullptr);
    }
    outcome.md_path = files.md.string();
    outcome.json_path = files.json.string();
    return outcome;
}

}  // namespace rcb

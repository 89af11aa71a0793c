// advise's steps alone: --method's parsing, the scene and parameter plans, the model method's
// candidates (their order, which are measured), the measured descent's neighbours and walk, the
// rows' plan and the reuse of the model's measurements, and the exhaustive comparison. The replay
// and the measurement are functions here, so the steps run on made-up costs, without a scene.
#include <gtest/gtest.h>

#include <cmath>

#include "accel/narrow/narrow_phase.h"
#include "accel/registry.h"
#include "core/base/error.h"
#include "tuner/advise.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// One dimension "a" with levels 1..n.
std::vector<SearchDimension> line_space(int n) {
    SearchDimension d{"a", {}};
    for (int i = 1; i <= n; ++i) d.levels.push_back(i);
    return {d};
}

MeasuredCost cost_of(double ms) {
    MeasuredCost c;
    c.ms = ms;
    return c;
}

/// What a replay of {"a": v} counts: distinct per level.
ReplayCounts counts_of(int a) {
    ReplayCounts r;
    r.counters.n_t = std::uint64_t(a);
    return r;
}

/// Records every measurement; the cost is `ms(a)`.
struct FakeMeasure {
    std::function<double(int)> ms;
    std::vector<int> calls;
    SceneMeasurement function() {
        return [this](const json& p) {
            calls.push_back(p["a"].get<int>());
            return cost_of(ms(p["a"].get<int>()));
        };
    }
};

/// A ranking as rank_by_model makes it: the levels evaluated with their predicted costs.
ModelRanking ranking_of(const std::vector<std::pair<int, double>>& predicted) {
    ModelRanking r;
    for (const auto& [a, ms] : predicted) {
        r.search.evaluations.push_back({json{{"a", a}}, ms});
        r.replays.entries.push_back({json{{"a", a}}, counts_of(a)});
    }
    return r;
}

TEST(AdviseSteps, MethodIsParsedOnceWithItsOptionInTheError) {
    EXPECT_EQ(parse_advise_method("auto"), AdviseMethod::automatic);
    EXPECT_EQ(parse_advise_method("category"), AdviseMethod::category);
    EXPECT_EQ(parse_advise_method("model"), AdviseMethod::model);
    try {
        parse_advise_method("Model");
        ADD_FAILURE() << "accepted Model";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("--method: expected auto, category or model"), std::string::npos);
    }
    EXPECT_EQ(method_name(ParameterMethod::model), "model");
    EXPECT_EQ(method_name(ParameterMethod::category), "category");
    EXPECT_FALSE(ParameterMethod::model == "category");
}

TEST(AdviseSteps, ACsvSceneIsImportedWithTenFrames) {
    const TuneCategory csv = advise_scene("maps/level.csv");
    EXPECT_EQ(csv.name, "level");
    ASSERT_EQ(csv.scenes.size(), 1u);
    EXPECT_EQ(csv.scenes[0].source, SceneSpec::Source::import);
    EXPECT_EQ(csv.scenes[0].settings.frames, 10u);
    const TuneCategory recording = advise_scene("a/b.rcbscene");
    EXPECT_EQ(recording.name, "b");
    EXPECT_EQ(recording.scenes[0].source, SceneSpec::Source::recording);
    EXPECT_EQ(recording.scenes[0].path, "a/b.rcbscene");
}

TEST(AdviseSteps, PlanParametersChoosesTheMethodPerStructureAndRefusesTheImpossible) {
    TuningSelection s;
    s.category = "c";
    TunedStructure ug;
    ug.params = find_structure("ug").defaults();
    ug.params["density"] = 2.0;
    ug.space = {{"density", {1.0, 2.0, 4.0}}};
    CostCoefficients by_hand;
    by_hand["C_RB"] = 1;
    by_hand["C_T"] = 10;
    by_hand.model = "by hand";
    ug.model = by_hand;
    TunedStructure hg;  // an older tuning: neither space nor model
    hg.params = find_structure("hg").defaults();
    s.tuned = {{"ug", ug}, {"hg", hg}};

    const ParameterPlan plan = plan_parameters(s, AdviseMethod::automatic, false, "t.json");
    EXPECT_EQ(plan.structures.size(), structure_registry().size());  // every structure, tuned or not
    ASSERT_EQ(plan.choices.size(), 2u);
    for (const ParameterChoice& pc : plan.choices) {
        if (pc.structure == "ug") {
            EXPECT_EQ(pc.method, ParameterMethod::model);
            EXPECT_EQ(pc.model, "by hand");
            EXPECT_EQ(pc.category_searched, (json{{"density", 2.0}}));
            EXPECT_EQ(pc.chosen_searched, pc.category_searched);
        } else {
            EXPECT_EQ(pc.method, ParameterMethod::category);
            EXPECT_NE(pc.why.find("no cost model"), std::string::npos) << pc.why;
        }
    }
    for (const ParameterChoice& pc : plan_parameters(s, AdviseMethod::category, false, "t.json").choices) {
        EXPECT_EQ(pc.method, ParameterMethod::category);
        EXPECT_EQ(pc.why, "--method category");
    }
    EXPECT_THROW(plan_parameters(s, AdviseMethod::model, false, "t.json"), InputError);     // hg has no model
    EXPECT_THROW(plan_parameters(s, AdviseMethod::automatic, true, "t.json"), InputError);  // nor a space
    s.tuned.erase("hg");
    EXPECT_NO_THROW(plan_parameters(s, AdviseMethod::model, true, "t.json"));
}

TEST(AdviseSteps, PredictionOrderIsStableOnTies) {
    const std::vector<Evaluation> e{{json{{"a", 1}}, 3}, {json{{"a", 2}}, 1}, {json{{"a", 3}}, 2}, {json{{"a", 4}}, 1}};
    EXPECT_EQ(prediction_order(e), (std::vector<std::size_t>{1, 3, 2, 0}));
}

TEST(AdviseSteps, TheBestPredictionsAreVerifiedOncePerStructureInEffect) {
    const std::vector<SearchDimension> space = line_space(5);
    ModelRanking r = ranking_of({{1, 5.0}, {2, 1.0}, {3, 2.0}, {4, 3.0}});
    r.replays.entries[2].second = counts_of(2);  // a=3 counts like a=2: the same structure in effect
    FakeMeasure m{[](int a) { return double(a); }, {}};
    ModelEvidence e = verify_candidates(r, space, json{{"a", 1}}, 2, m.function());
    // a=2 and a=4 (a=3 is a=2 again), then the category's a=1 beside them.
    EXPECT_EQ(m.calls, (std::vector<int>{2, 4, 1}));
    ASSERT_EQ(e.candidates.size(), 4u);
    EXPECT_EQ(e.candidates[0].searched["a"], 2);  // by prediction
    EXPECT_EQ(e.candidates[1].searched["a"], 3);
    EXPECT_FALSE(e.candidates[1].measured.has_value());
    EXPECT_TRUE(e.candidates[3].is_category);
    EXPECT_EQ(e.measured_counts.size(), 3u);

    // --verify-top 0, the pure model: nothing measured, the category's neither.
    m.calls.clear();
    e = verify_candidates(r, space, json{{"a", 1}}, 0, m.function());
    EXPECT_TRUE(m.calls.empty());
    // The category's parameters, not replayed by the search, join without a prediction.
    m.calls.clear();
    e = verify_candidates(r, space, json{{"a", 5}}, 1, m.function());
    EXPECT_EQ(m.calls, (std::vector<int>{2, 5}));
    ASSERT_EQ(e.candidates.size(), 5u);
    EXPECT_TRUE(e.candidates.back().is_category);
    EXPECT_FALSE(e.candidates.back().predicted_ms.has_value());
}

TEST(AdviseSteps, DescentNeighboursAreOneDimensionAtATimeUpThenDown) {
    const std::vector<SearchDimension> space{{"a", {1, 2, 3, 4}}, {"b", {"x", "y"}}};
    const json from{{"a", 2}, {"b", "x"}};
    EXPECT_EQ(descent_neighbours(space, from, 1),
              (std::vector<json>{{{"a", 3}, {"b", "x"}}, {{"a", 1}, {"b", "x"}}, {{"a", 2}, {"b", "y"}}}));
    EXPECT_EQ(descent_neighbours(space, from, 2), (std::vector<json>{{{"a", 4}, {"b", "x"}}}));
    // 2.0 is the level 2; a level not in the space and a missing dimension have no neighbours.
    EXPECT_EQ(descent_neighbours(space, json{{"a", 2.0}}, 1).size(), 2u);
    EXPECT_TRUE(descent_neighbours(space, json{{"a", 7}}, 1).empty());
    EXPECT_TRUE(descent_neighbours(space, json::object(), 1).empty());
}

TEST(AdviseSteps, TheDescentWalksToTheMeasuredOptimumWithinItsMeasurements) {
    const std::vector<SearchDimension> space = line_space(8);
    auto run = [&](std::uint32_t refine, const std::function<double(int)>& ms, std::vector<int>* calls) {
        FakeMeasure m{ms, {}};
        ModelEvidence e;
        e.candidates.push_back({json{{"a", 2}}, 1.0, cost_of(ms(2)), true});
        e.replays.entries.push_back({json{{"a", 2}}, counts_of(2)});
        e.measured_counts.push_back(counts_of(2));
        std::size_t replays = 0;
        const ReplayPrediction predict = [&](const json& p, ReplayCounts& counts) {
            ++replays;
            counts = counts_of(p["a"].get<int>());
            return 0.0;
        };
        refine_by_descent(e, {space, json{{"a", 2}}, refine, AccuracyConstraint{}}, predict, m.function());
        EXPECT_EQ(replays, m.calls.size());  // each level replayed once, before it is measured
        order_candidates(e.candidates, AccuracyConstraint{});
        if (calls) *calls = m.calls;
        EXPECT_EQ(e.refined, m.calls.size());
        return e;
    };
    const auto valley = [](int a) { return std::abs(a - 6) + 1.0; };
    std::vector<int> calls;
    ModelEvidence e = run(10, valley, &calls);
    // Up one level while faster; at 6, 7 is slower and 5 measured already; two levels: 8, and 4 known.
    EXPECT_EQ(calls, (std::vector<int>{3, 4, 5, 6, 7, 8}));
    EXPECT_EQ(e.candidates.front().searched["a"], 6);
    e = run(2, valley, &calls);  // two measurements: 3, 4
    EXPECT_EQ(calls, (std::vector<int>{3, 4}));
    EXPECT_EQ(e.candidates.front().searched["a"], 4);
    // A bump at 3: one level finds nothing faster, two levels away does.
    e = run(
        3, [](int a) { return a == 4   ? 1.0
                              : a == 3 ? 9.0
                                       : 10.0 - a; }, &calls);
    EXPECT_EQ(calls, (std::vector<int>{3, 1, 4}));
    EXPECT_EQ(e.candidates.front().searched["a"], 4);
    e = run(0, valley, &calls);
    EXPECT_TRUE(calls.empty());
}

TEST(AdviseSteps, CandidatesAreOrderedMeasuredFirstThenByPrediction) {
    MeasuredCost inexact = cost_of(0.5);
    inexact.accuracy.exact_level = false;  // candidates level: fails exact however fast
    std::vector<ModelCandidate> c{
        {json{{"a", 1}}, 1.0, std::nullopt, false}, {json{{"a", 2}}, std::nullopt, std::nullopt, true},
        {json{{"a", 3}}, 9.0, cost_of(2.0), false}, {json{{"a", 4}}, 0.5, std::nullopt, false},
        {json{{"a", 5}}, 8.0, inexact, false},      {json{{"a", 6}}, 7.0, cost_of(1.0), false}};
    order_candidates(c, AccuracyConstraint{});
    std::vector<int> order;
    for (const ModelCandidate& m : c) order.push_back(m.searched["a"].get<int>());
    EXPECT_EQ(order, (std::vector<int>{6, 3, 5, 4, 1, 2}));
    EXPECT_TRUE(measured_faster(cost_of(1.0), inexact, AccuracyConstraint{}));
    EXPECT_FALSE(measured_faster(inexact, cost_of(1.0), AccuracyConstraint{}));
}

TEST(AdviseSteps, RowsAddQueryLevelsWhenInexactAnswersAreAllowedAndReuseTheModelsMeasurement) {
    const StructureInfo& ug = find_structure("ug");
    const StructureInfo& bf = find_structure("bf");
    const std::vector<StructurePlan> structures{{&bf, bf.complete(json::object(), "bf")},
                                                {&ug, ug.complete(json{{"density", 4.0}}, "ug")}};
    ParameterChoice pc;
    pc.structure = "ug";
    pc.method = ParameterMethod::model;
    pc.space = {{"density", {2.0, 4.0}}};
    pc.chosen_searched = {{"density", 4.0}};
    pc.candidates = {{json{{"density", 2.0}}, 1.0, cost_of(7.0), false},
                     {json{{"density", 4.0}}, 2.0, cost_of(3.0), false}};

    RowPlan exact = plan_rows(structures, {pc}, AccuracyConstraint{});
    ASSERT_EQ(exact.rows.size(), 2u);
    EXPECT_FALSE(exact.rows[0].tuned);
    EXPECT_TRUE(exact.rows[1].tuned);
    std::vector<std::string> measured;
    measure_rows(exact, {pc},
                 [&](const std::string& s, const json&) {
                     measured.push_back(s);
                     return cost_of(1.0);
                 },
                 {});
    EXPECT_EQ(measured, (std::vector<std::string>{"bf"}));  // ug's row is the model's measurement
    EXPECT_EQ(exact.rows[1].cost.ms, 3.0);

    const RowPlan inexact = plan_rows(structures, {pc}, parse_accuracy("recall>=0.9"));
    ASSERT_EQ(inexact.rows.size(), 6u);
    std::vector<QueryLevel> levels;
    for (const json& p : inexact.params) levels.push_back(query_level_of(p));
    using enum QueryLevel;
    EXPECT_EQ(levels, (std::vector<QueryLevel>{boxes, candidates, shapes, boxes, candidates, shapes}));
    for (std::size_t i = 0; i < inexact.rows.size(); ++i) EXPECT_EQ(inexact.rows[i].params, inexact.params[i].dump());
}

TEST(AdviseSteps, TheExhaustiveComparisonPricesOutWhatFailsTheAccuracy) {
    ParameterChoice pc;
    pc.structure = "ug";
    pc.space = line_space(3);
    pc.chosen_searched = {{"a", 2}};
    pc.category_searched = {{"a", 3}};
    MeasuredCost fast_but_inexact = cost_of(0.1);
    fast_but_inexact.accuracy.exact_level = false;
    const std::vector<MeasuredCost> table{fast_but_inexact, cost_of(2.0), cost_of(4.0)};
    // The re-measurement: every choice and the table's best again, each 10% slower.
    std::vector<std::size_t> asked;
    const Rescore rescore = [&](const std::vector<std::size_t>& indices) {
        asked = indices;
        std::vector<MeasuredCost> out;
        for (const std::size_t i : indices) {
            MeasuredCost c = table[i];
            c.ms *= 1.1;
            out.push_back(c);
        }
        return out;
    };
    const ExhaustiveAdvice e = compare_exhaustively(pc, {json{{"a", 1}}, json{{"a", 2}}, json{{"a", 3}}}, table,
                                                    AccuracyConstraint{}, rescore);
    EXPECT_EQ(e.configurations, 3u);
    EXPECT_EQ(e.best_searched, (json{{"a", 2}}));
    EXPECT_EQ(e.best_table_ms, 2.0);
    EXPECT_DOUBLE_EQ(e.best_ms, 2.2);  // re-measured
    EXPECT_EQ(asked.front(), 1u);      // the table's best first
    EXPECT_EQ(e.rescored, asked.size());
    EXPECT_DOUBLE_EQ(e.advised_gap(), 0.0);
    EXPECT_DOUBLE_EQ(e.category_gap(), 1.0);
}

}  // namespace
}  // namespace rcb

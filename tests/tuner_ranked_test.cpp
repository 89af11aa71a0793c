// The measured mode's ranked method (rank_then_time, tuner/search.h): never more timings than the
// budget, the fastest of what it timed, the optimum within the budget where the model ranks
// right, a measured configuration where it ranks wrong; in a tuning (made-up times from the
// counters, TuneCategory::timing) and in the equal-budget comparison (tuner/search_baselines.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "accel/registry.h"
#include "tests/test_scenes.h"
#include "tests/test_timing.h"
#include "tuner/search.h"
#include "tuner/search_baselines.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// 12 configurations in 8 classes: 0–3 alone, then pairs {4, 5}, {6, 7}, {8, 9}, {10, 11}.
std::vector<std::size_t> paired_classes() { return {0, 1, 2, 3, 4, 4, 5, 5, 6, 6, 7, 7}; }

TEST(RankThenTime, TimesExactlyTheBudgetOfDistinctClassesAndKeepsTheFastest) {
    const std::vector<std::size_t> class_of = paired_classes();
    const std::vector<double> cost = {9, 8, 7, 6, 5, 5, 4, 4, 3, 3, 2, 2};       // class 7 is the optimum
    const std::vector<double> predicted = {1, 2, 3, 4, 5, 5, 6, 6, 7, 7, 8, 8};  // ranks it last
    for (std::size_t budget : {1u, 3u, 5u, 8u, 20u}) {
        std::vector<std::size_t> calls;
        const RankedResult r = rank_then_time(class_of, predicted, budget, [&](std::size_t i) {
            calls.push_back(i);
            return cost[i];
        });
        const std::size_t expected = std::min<std::size_t>(budget, 8);
        EXPECT_EQ(calls.size(), expected) << "budget " << budget;
        EXPECT_EQ(r.timed, calls);
        std::set<std::size_t> classes;
        for (std::size_t i : calls) classes.insert(class_of[i]);
        EXPECT_EQ(classes.size(), calls.size()) << "a class timed twice";
        // In the model's order (a class's first member), and the fastest of those timed kept.
        for (std::size_t k = 1; k < calls.size(); ++k) EXPECT_LT(predicted[calls[k - 1]], predicted[calls[k]]);
        ASSERT_LT(r.best, r.timed.size());
        EXPECT_DOUBLE_EQ(r.costs[r.best], *std::min_element(r.costs.begin(), r.costs.end()));
    }
}

TEST(RankThenTime, ARightRankingFindsTheOptimumWithinTheBudget) {
    // A model off by a constant and a factor, with a little noise that never swaps two classes:
    // its best-ranked class is the optimum, found by the first timing.
    const std::vector<std::size_t> class_of = paired_classes();
    const std::vector<double> cost = {4.0, 2.5, 3.0, 1.2, 6.0, 6.1, 1.0, 1.02, 2.0, 2.0, 5.0, 5.05};
    std::vector<double> predicted;
    for (std::size_t i = 0; i < cost.size(); ++i)
        predicted.push_back(0.3 + 0.8 * cost[i] * (1 + 0.001 * double(i % 3)));
    std::size_t calls = 0;
    const RankedResult r = rank_then_time(class_of, predicted, 2, [&](std::size_t i) { return ++calls, cost[i]; });
    EXPECT_EQ(calls, 2u);
    EXPECT_EQ(r.timed.front(), 6u);  // the optimum's class, at its first member
    EXPECT_DOUBLE_EQ(r.costs[r.best], 1.0);
}

TEST(RankThenTime, AWrongRankingStillReturnsAMeasuredConfiguration) {
    const std::vector<std::size_t> class_of = paired_classes();
    const std::vector<double> cost = {9, 8, 7, 6, 5, 5, 4, 4, 3, 3, 2, 2};
    const std::vector<double> reversed = {1, 2, 3, 4, 5, 5, 6, 6, 7, 7, 8, 8};
    const RankedResult r = rank_then_time(class_of, reversed, 2, [&](std::size_t i) { return cost[i]; });
    ASSERT_EQ(r.timed.size(), 2u);
    EXPECT_EQ(r.timed[r.best], 1u);  // the faster of the two timed, far from the optimum
    EXPECT_DOUBLE_EQ(r.costs[r.best], 8.0);
    // No model at all (every prediction NaN): the space's order, still timed and measured.
    const RankedResult none =
        rank_then_time(class_of, std::vector<double>(12, NAN), 3, [&](std::size_t i) { return cost[i]; });
    EXPECT_EQ(none.timed, (std::vector<std::size_t>{0, 1, 2}));
    EXPECT_DOUBLE_EQ(none.costs[none.best], 7.0);
    // Every timing failed: the first timed is returned, not an index past the end.
    const RankedResult failed = rank_then_time(class_of, reversed, 3, [](std::size_t) { return NAN; });
    EXPECT_EQ(failed.best, 0u);
    EXPECT_EQ(failed.timed.size(), 3u);
}

TEST(RankThenTime, ARefitReranksTheClassesNotTimedYet) {
    // The first model ranks the optimum (class 7) last; a refit after the first timing ranks it
    // first, so the second timing takes it. The refit is not asked after the last timing.
    const std::vector<std::size_t> class_of = paired_classes();
    const std::vector<double> cost = {9, 8, 7, 6, 5, 5, 4, 4, 3, 3, 2, 2};
    const std::vector<double> wrong = {1, 2, 3, 4, 5, 5, 6, 6, 7, 7, 8, 8};
    std::vector<std::size_t> refit_sizes;
    const RankedResult r = rank_then_time(
        class_of, wrong, 3, [&](std::size_t i) { return cost[i]; },
        [&](const std::vector<std::size_t>& timed) -> std::optional<std::vector<double>> {
            refit_sizes.push_back(timed.size());
            if (timed.size() > 1) return std::nullopt;  // a fit that gives nothing keeps the model
            return cost;
        });
    EXPECT_EQ(refit_sizes, (std::vector<std::size_t>{1, 2}));
    EXPECT_EQ(r.refits, 1u);
    EXPECT_EQ(r.timed, (std::vector<std::size_t>{0, 10, 8}));
    EXPECT_DOUBLE_EQ(r.costs[r.best], 2.0);
}

/// Micro-scene costs as a calibration would fit them: these values, pinned.
ModelInputs calibration_of(const std::string& structure, double c_rb, double c_t, double c_prep) {
    StructureCalibration c;
    c.structure = structure;
    c.terms = {{"C_RB", c_rb, c_rb, c_rb, true, ""},
               {"C_T", c_t, c_t, c_t, true, ""},
               {"C_PREP", c_prep, c_prep, c_prep, true, ""}};
    ModelInputs in;
    in.calibrations.push_back(c);
    return in;
}

TuneSpec ranked_spec(std::size_t budget) {
    TuneSpec spec =
        parse_tune_spec(R"({"structures": ["ug"], "mode": "measured", "budget": )" + std::to_string(budget) +
                            R"(, "frames": 3, "rays_per_frame": 200, "repetitions": 2,
            "space": {"ug": {"density": [0.125, 0.25, 0.5, 1, 2, 4, 8, 16]}},
            "categories": [{"name": "u", "scenes": [{"generator": "irregular", "objects": 2000}]}]})",
                        "t.json", ".");
    // Made-up times from the counters (C_RB 2, C_T 20, C_PREP 50 ns), so the verdicts do not follow
    // the clock of a loaded machine.
    spec.categories[0].timing = test::counted_timing(2.0, 20.0, 50.0);
    return spec;
}

/// Every configuration of the spec's ug space measured as the tuner measures (made-up times).
std::vector<double> exhaustive_ms(const TuneSpec& spec) {
    std::vector<json> params;
    for (const json& p : enumerate_space(spec.space.at("ug"))) {
        json full = find_structure("ug").defaults();
        for (const auto& [k, v] : p.items()) full[k] = v;
        params.push_back(full);
    }
    std::vector<double> out;
    for (const MeasuredCost& m :
         measure_interleaved(spec.categories[0], "ug", params, spec.warmup_frames, spec.repetitions))
        out.push_back(m.ms);
    return out;
}

/// The lowest measured cost among a tuning's candidates (each must have been measured).
double fastest_measured(const StructureTuning& st) {
    double fastest = INFINITY;
    for (const Candidate& c : st.candidates) {
        EXPECT_TRUE(c.measured) << c.params.dump();
        if (c.measured) fastest = std::min(fastest, c.measured->ms);
    }
    return fastest;
}

TEST(TuneRanked, AMeasuredTuningTimesTheBudgetAndFindsTheOptimumWhereTheModelIsRight) {
    const TuneSpec spec = ranked_spec(3);
    const std::vector<double> all = exhaustive_ms(spec);
    const double optimum = *std::min_element(all.begin(), all.end());
    // The machine's calibration as the made-up times price the rays: the ranking is right.
    MachinePriors priors;
    priors.set("ug", calibration_of("ug", 2.0, 20.0, 50.0));
    const SimulationTally before = simulation_tally();
    const CategoryTuning t = tune_category(spec, spec.categories[0], &priors);
    const SimulationTally after = simulation_tally();
    ASSERT_EQ(t.structures.size(), 1u);
    const StructureTuning& st = t.structures[0];
    // Three configurations timed, each with its two repetitions on the one scene, nothing else;
    // the space replayed untimed to rank it (and each timed one replayed for its counters).
    EXPECT_EQ(st.measurements, 3u);
    EXPECT_EQ(st.candidates.size(), 3u);
    EXPECT_EQ(after.timed - before.timed, 3u * spec.repetitions);
    EXPECT_EQ(st.space_replays.size(), 8u);
    EXPECT_EQ(after.counting - before.counting, 8u + 3u);
    EXPECT_EQ(st.search.evaluations.size(), 3u);
    EXPECT_EQ(st.search.stop_reason, "budget");
    EXPECT_NE(st.search.algorithm.find("ranked"), std::string::npos) << st.search.algorithm;
    // The fastest of what it timed, each timed one priced when chosen, and that is the optimum.
    for (const Candidate& c : st.candidates) EXPECT_TRUE(c.predicted_ms) << c.params.dump();
    const double fastest = fastest_measured(st);
    EXPECT_DOUBLE_EQ(st.candidates[st.best_candidate].measured->ms, fastest);
    EXPECT_NEAR(fastest, optimum, 1e-12 * optimum);
    // The first configuration timed is the model's best.
    EXPECT_DOUBLE_EQ(st.search.evaluations.front().cost, optimum);
}

TEST(TuneRanked, WhereTheModelIsWrongItStillReturnsTheFastestItMeasured) {
    // A calibration that prices a box test at 50× a cell step, where the made-up times price a
    // cell step at 10× a box test: a ranking by the wrong balance. Four timings leave one after a
    // refit on three configurations' frames.
    const TuneSpec spec = ranked_spec(4);
    MachinePriors priors;
    priors.set("ug", calibration_of("ug", 100.0, 2.0, 1.0));
    const SimulationTally before = simulation_tally();
    const CategoryTuning t = tune_category(spec, spec.categories[0], &priors);
    const SimulationTally after = simulation_tally();
    ASSERT_EQ(t.structures.size(), 1u);
    const StructureTuning& st = t.structures[0];
    EXPECT_EQ(st.measurements, 4u);
    EXPECT_EQ(after.timed - before.timed, 4u * spec.repetitions);
    ASSERT_EQ(st.search.evaluations.size(), 4u);
    const double fastest = fastest_measured(st);
    EXPECT_DOUBLE_EQ(st.candidates[st.best_candidate].measured->ms, fastest);
    EXPECT_DOUBLE_EQ(st.search.evaluations[st.search.best].cost, fastest);
    EXPECT_LE(st.refits, 1u);  // asked once, after the third timing
    ASSERT_TRUE(st.cost_model.has_value());
}

TEST(TuneRanked, WithoutAModelTheMeasuredModeSearches) {
    // No machine calibration to rank by: the search from the defaults, as before.
    const TuneSpec spec = ranked_spec(3);
    const CategoryTuning t = tune_category(spec, spec.categories[0]);
    ASSERT_EQ(t.structures.size(), 1u);
    EXPECT_TRUE(t.structures[0].space_replays.empty());
    EXPECT_EQ(t.structures[0].search.algorithm.find("ranked"), std::string::npos);
    EXPECT_LE(t.structures[0].measurements, 3u);
}

TEST(TuneRanked, TheComparisonGivesTheRankedMethodTheSameBudget) {
    // 10 × 4 configurations, b changes nothing; budget 30% of 10 classes = 3.
    std::vector<SearchDimension> dims = {{"a", {}}, {"b", {}}};
    for (int i = 0; i < 10; ++i) dims[0].levels.push_back(i);
    for (int i = 0; i < 4; ++i) dims[1].levels.push_back(i);
    const std::vector<json> all = enumerate_space(dims);
    std::vector<double> costs, right, wrong;
    std::vector<std::size_t> class_of;
    for (const json& p : all) {
        const int a = p["a"].get<int>();
        costs.push_back(1.0 + 0.1 * std::abs(a - 8));
        right.push_back(std::abs(a - 8) + 0.5);
        wrong.push_back(-std::abs(a - 8));
        class_of.push_back(std::size_t(a));
    }
    std::size_t refits_asked = 0;
    RankedInputs in{wrong,
                    [&](const std::vector<std::size_t>&) -> std::optional<std::vector<double>> {
                        ++refits_asked;
                        return right;
                    },
                    40};
    const BudgetComparison c =
        compare_at_equal_budget(dims, all, costs, class_of, {{"a", 2}, {"b", 0}}, 0.3, 1, 1, {}, 0, &in);
    EXPECT_EQ(c.budget, 3u);
    EXPECT_EQ(c.ranked_timed, 3u);
    EXPECT_EQ(c.ranked_replays, 40u);
    EXPECT_EQ(refits_asked, 2u);  // after the first and second timing, not the last
    EXPECT_EQ(c.ranked_refits, 2u);
    EXPECT_DOUBLE_EQ(c.ranked_regret, 0.0);  // the refit's ranking reaches a = 8
    // Alone, the wrong ranking times a = 0, 1, 2 (the farthest from the optimum first): a = 2 costs 1.6.
    EXPECT_NEAR(c.ranked_unrefitted_regret, 1.6 / c.optimum - 1, 1e-12);
    EXPECT_DOUBLE_EQ(c.tuner(), c.ranked_regret);
    // Summarised: the tuner is the ranked method where it ran, the search elsewhere.
    BudgetComparison searched = c;
    searched.ranked_regret = NAN;
    const SuiteSummary s = summarize_suite({c, searched});
    EXPECT_EQ(s.ranked_problems, 1u);
    EXPECT_NEAR(s.running_median, (0.0 + c.tuner_regret) / 2, 1e-12);
    EXPECT_DOUBLE_EQ(s.median_replays, 40.0);
}

}  // namespace
}  // namespace rcb

// The tuner's search at a tenth of the space: it reaches the exact optimum of known cost surfaces
// for five seeds, counts its start point, is deterministic per seed; Spearman's rank correlation;
// and the exhaustive check's one counting replay per configuration.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>

#include "tests/test_scenes.h"
#include "tests/test_support.h"
#include "tuner/run_tuning.h"
#include "tuner/search.h"
#include "tuner/search_baselines.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// Shaped like experiments/tune-validate.json's HG space (4 × 4 × 3 × 2 = 96): a valley in
/// (amp, depth) with a mild interaction, capacity with a shallow optimum inside its range, and
/// a choice that matters a little. The defaults (the start) are two levels from the optimum.
std::vector<SearchDimension> validate_like_space() {
    return {{"amp", {0.25, 0.5, 1.0, 2.0}},
            {"max_depth", {0, 1, 2, 3}},
            {"max_capacity", {8, 16, 32}},
            {"subdivision", {2, 3}}};
}

double validate_like_cost(const json& p) {
    const double amp = std::log2(p["amp"].get<double>()), depth = p["max_depth"].get<double>();
    const double capacity = std::log2(p["max_capacity"].get<double>());
    const double sub = p["subdivision"].get<double>();
    return 1.0 + 0.12 * (amp + 0.9) * (amp + 0.9) + 0.08 * (depth - 1.8) * (depth - 1.8) +
           0.03 * (amp + 0.9) * (depth - 1.8) + 0.02 * std::abs(capacity - 4.2) + 0.01 * (sub == 2 ? 1 : 0);
}

/// 6 × 5 × 4 × 2 = 240 points, the valley off-centre in every dimension.
std::vector<SearchDimension> wide_space() {
    return {
        {"a", {0.125, 0.25, 0.5, 1.0, 2.0, 4.0}}, {"b", {0, 1, 2, 3, 4}}, {"c", {4, 8, 16, 32}}, {"d", {false, true}}};
}

double wide_cost(const json& p) {
    const double a = std::log2(p["a"].get<double>()), b = p["b"].get<double>(), c = std::log2(p["c"].get<double>());
    return 2.0 + 0.1 * (a - 1.3) * (a - 1.3) + 0.15 * (b - 0.6) * (b - 0.6) + 0.05 * std::abs(c - 2.1) +
           0.02 * (a - 1.3) * (b - 0.6) + (p["d"].get<bool>() ? 0.0 : 0.03);
}

void expect_optimum_within_a_tenth(const std::vector<SearchDimension>& dims,
                                   const std::function<double(const json&)>& cost, const json& start) {
    const std::vector<json> all = enumerate_space(dims);
    double optimum = INFINITY;
    for (const json& p : all) optimum = std::min(optimum, cost(p));
    const std::size_t budget = all.size() / 10;
    for (std::uint64_t seed = 1; seed <= 5; ++seed) {
        std::size_t calls = 0;
        const SearchResult r = search_levels(
            dims, [&](const json& p) { return ++calls, cost(p); }, budget, seed, start);
        EXPECT_LE(r.evaluations.size(), budget) << "seed " << seed;
        EXPECT_EQ(calls, r.evaluations.size()) << "seed " << seed;  // memoised
        ASSERT_FALSE(r.evaluations.empty());
        EXPECT_EQ(r.evaluations.front().params, start) << "seed " << seed;  // the start is evaluated first
        EXPECT_DOUBLE_EQ(r.evaluations[r.best].cost, optimum) << "seed " << seed;
        // The same seed gives the same evaluations.
        const SearchResult again = search_levels(dims, cost, budget, seed, start);
        ASSERT_EQ(again.evaluations.size(), r.evaluations.size());
        for (std::size_t i = 0; i < r.evaluations.size(); ++i)
            EXPECT_EQ(again.evaluations[i].params, r.evaluations[i].params) << "seed " << seed << " evaluation " << i;
    }
}

TEST(TunerSearchBudget, FindsTheOptimumOfAValidateLikeSpaceWithATenthOfItsPointsForFiveSeeds) {
    expect_optimum_within_a_tenth(validate_like_space(), validate_like_cost,
                                  {{"amp", 1.0}, {"max_depth", 3}, {"max_capacity", 16}, {"subdivision", 2}});
}

TEST(TunerSearchBudget, FindsTheOptimumOfAWiderSpaceWithATenthOfItsPointsForFiveSeeds) {
    expect_optimum_within_a_tenth(wide_space(), wide_cost, {{"a", 0.5}, {"b", 2}, {"c", 8}, {"d", false}});
}

using PerMille = int[4][4][6];

/// A surface of tune-validate.json's HG space as `table` gives it (per mille above the best),
/// [amp][max_depth][max_capacity × subdivision].
double validate_cost(const PerMille& table, const json& p) {
    const int amp = int(std::lround(std::log2(p["amp"].get<double>()))) + 2;
    const int depth = p["max_depth"].get<int>();
    const int capacity = int(std::lround(std::log2(p["max_capacity"].get<double>()))) - 3;
    const int sub = p["subdivision"].get<int>() - 2;
    return 1.0 + table[amp][depth][capacity * 2 + sub] / 1000.0;
}

/// tune-validate.json's HG space as measured on irreg-m (the mean of repeated exhaustive runs): a
/// valley in amp at 0.5, depth cheap only at the largest capacity or at 0, and subdivision 3
/// better than 2 at the defaults' amp but not at the optimum's, so a step that pays at the start
/// leads away from it.
double measured_validate_cost(const json& p) {
    static const PerMille kPerMille = {
        {{102, 84, 86, 89, 90, 88},
         {411, 666, 81, 207, 74, 172},
         {555, 835, 142, 306, 87, 208},
         {623, 938, 204, 326, 96, 242}},
        {{16, 7, 12, 8, 23, 10}, {135, 294, 62, 99, 0, 6}, {263, 356, 100, 181, 8, 47}, {330, 420, 122, 184, 47, 55}},
        {{131, 126, 137, 122, 127, 129},
         {227, 260, 173, 298, 148, 255},
         {293, 370, 271, 209, 195, 257},
         {314, 429, 233, 263, 156, 264}},
        {{306, 299, 310, 297, 298, 300},
         {512, 443, 447, 360, 373, 283},
         {492, 551, 377, 387, 293, 474},
         {518, 525, 486, 413, 334, 482}},
    };
    return validate_cost(kPerMille, p);
}

/// One exhaustive run of the same space on irreg-m as measured, noise and all: at the defaults'
/// depth and capacity subdivision 3 beats 2 while amp 0.5 loses to amp 1, so a search that steps
/// in subdivision first stops in a coordinate-wise minimum about a fifth above the optimum.
double measured_validate_decoy_cost(const json& p) {
    static const PerMille kPerMille = {
        {{126, 116, 87, 104, 101, 113},
         {405, 719, 141, 281, 60, 177},
         {580, 813, 178, 304, 88, 212},
         {666, 934, 213, 319, 101, 241}},
        {{8, 2, 7, 25, 20, 11}, {125, 294, 58, 71, 0, 10}, {274, 428, 104, 252, 15, 87}, {412, 494, 148, 169, 60, 75}},
        {{213, 200, 201, 178, 148, 130},
         {211, 283, 196, 309, 146, 232},
         {294, 325, 276, 233, 254, 317},
         {362, 417, 256, 330, 221, 312}},
        {{357, 290, 290, 314, 374, 362},
         {598, 485, 488, 437, 451, 334},
         {557, 626, 420, 442, 357, 567},
         {608, 576, 539, 446, 432, 575}},
    };
    return validate_cost(kPerMille, p);
}

TEST(TunerSearchBudget, ReachesTheInteractingOptimumOfMeasuredValidateSpacesForTwentySeeds) {
    // From the defaults with tune-validate.json's budget of 9 (a tenth of 96): the optimum needs
    // amp and depth both to move, and cheap early steps in subdivision or capacity lead elsewhere.
    const json defaults{{"amp", 1.0}, {"max_depth", 2}, {"max_capacity", 16}, {"subdivision", 2}};
    for (const auto& cost : {measured_validate_cost, measured_validate_decoy_cost})
        for (std::uint64_t seed = 1; seed <= 20; ++seed) {
            const SearchResult r = search_levels(validate_like_space(), cost, 9, seed, defaults);
            EXPECT_LE(r.evaluations.size(), 9u);
            EXPECT_LE(r.evaluations[r.best].cost, 1.02) << "seed " << seed << ": " << r.evaluations[r.best].params;
        }
}

TEST(TunerSearchBudget, WithoutAStartTheMiddleLevelsStart) {
    const SearchResult r = search_levels(validate_like_space(), validate_like_cost, 9, 1);
    ASSERT_FALSE(r.evaluations.empty());
    EXPECT_EQ(r.evaluations.front().params,
              (json{{"amp", 0.5}, {"max_depth", 1}, {"max_capacity", 16}, {"subdivision", 2}}));
}

TEST(TunerExhaustiveCheck, TheSearchReplayedOnAMeasuredSurfaceFindsItsOptimum) {
    // tune --exhaustive replays the search on the measured surface, one run per seed from the
    // spec's: a surface as large as the budget is enumerated and its optimum found by every seed.
    const std::vector<SearchDimension> dims = validate_like_space();
    std::map<std::string, double> surface;
    double best = INFINITY;
    for (const json& p : enumerate_space(dims)) {
        surface[p.dump()] = validate_like_cost(p);
        best = std::min(best, surface[p.dump()]);
    }
    const json start{{"amp", 1.0}, {"max_depth", 2}, {"max_capacity", 16}, {"subdivision", 2}};
    const std::vector<SurfaceReplay> all = replay_search_on_surface(dims, surface, 96, 7, 3, start);
    ASSERT_EQ(all.size(), 3u);
    for (std::size_t i = 0; i < all.size(); ++i) {
        EXPECT_EQ(all[i].seed, 7 + i);
        EXPECT_EQ(all[i].evaluations, 96u);
        EXPECT_EQ(all[i].best_ms, best);
        EXPECT_EQ(surface.at(all[i].best_params.dump()), best);
    }
    // Within a tenth of the space, each seed stays within its budget and reports what it evaluated.
    for (const SurfaceReplay& r : replay_search_on_surface(dims, surface, 10, 1, 5, start)) {
        EXPECT_LE(r.evaluations, 10u);
        EXPECT_EQ(surface.at(r.best_params.dump()), r.best_ms);
        EXPECT_GE(r.best_ms, best);
    }
    // A surface without a configuration of the space is a caller's mistake, not a silent skip.
    surface.erase(start.dump());
    EXPECT_THROW(replay_search_on_surface(dims, surface, 96, 1, 1, start), std::out_of_range);
}

TEST(Spearman, RanksWithTiesAndTheDegenerateCases) {
    EXPECT_DOUBLE_EQ(spearman({1, 2, 3, 4}, {10, 20, 30, 40}), 1.0);
    EXPECT_DOUBLE_EQ(spearman({1, 2, 3, 4}, {4, 3, 2, 1}), -1.0);
    EXPECT_DOUBLE_EQ(spearman({1, 2, 3, 4, 5}, {1, 4, 9, 16, 25}), 1.0);  // monotone, not linear
    // Textbook: ranks (1,2,3,4,5) against (2,1,4,3,5): 1 − 6·Σd²/(n(n²−1)) = 1 − 6·4/120 = 0.8.
    EXPECT_NEAR(spearman({1, 2, 3, 4, 5}, {2, 1, 4, 3, 5}), 0.8, 1e-12);
    // Ties take their mean rank: (1, 2.5, 2.5, 4) against (1, 2, 3, 4).
    EXPECT_NEAR(spearman({1, 2, 2, 3}, {1, 2, 3, 4}), 4.5 / std::sqrt(4.5 * 5.0), 1e-12);
    EXPECT_TRUE(std::isnan(spearman({1, 1, 1}, {1, 2, 3})));
    EXPECT_TRUE(std::isnan(spearman({1}, {1})));
}

TEST(TunerExhaustiveCheck, ReplaysFiveSeedsOnTheMeasuredSurfaceAndRanksThePrediction) {
    namespace fs = std::filesystem;
    const test::TempDir temp("tuner", "exhaustive");
    const fs::path& dir = temp.path();
    const TuneSpec spec = parse_tune_spec(
        R"({"name": "ex", "mode": "measured", "structures": ["ug"], "budget": 3, "calibration": 4, "seed": 7,
            "frames": 3, "rays_per_frame": 200, "repetitions": 1,
            "space": {"ug": {"density": {"from": 0.25, "to": 16, "times": 2}}},
            "categories": [{"name": "small", "scenes": [{"generator": "irregular", "objects": 1500}]}]})",
        "ex.json", ".");
    TuneOptions o;
    o.file = (dir / "ex.json").string();
    o.db = (dir / "t.db").string();
    o.out_dir = dir.string();
    o.exhaustive = true;
    const SimulationTally before = simulation_tally();
    const TuneOutcome out = run_tuning(spec, o);
    const SimulationTally after = simulation_tally();
    // Counting replays: one per candidate the tuning timed (its counters, for the cost model); one
    // per configuration of the space, which prices it for the rankings and merges it with those
    // that count alike (the ranked method's replays where the tuning ran it, reused by the check);
    // one per configuration the check times, counting its frames for the ranked method's refits.
    ASSERT_EQ(out.categories.size(), 1u);
    const StructureTuning& st = out.categories[0].structures[0];
    EXPECT_EQ(after.counting - before.counting, st.measurements + 7 + 7);
    const json j = json::parse(std::ifstream(out.json_path));
    const json& ex = j["categories"][0]["exhaustive"][0];
    ASSERT_EQ(ex["surface"].size(), 7u);  // densities 0.25 … 16
    // The optimum is the table's best; its cost, like every choice's, is the second measurement's.
    double optimum = INFINITY, rescored = NAN;
    std::map<std::string, double> second;  // params → re-measured ms
    for (const json& e : ex["surface"]) {
        EXPECT_GT(e["ms"].get<double>(), 0);
        EXPECT_GT(e["rescored_ms"].get<double>(), 0);
        EXPECT_GT(e["predicted_ms"].get<double>(), 0);
        second[e["params"].dump()] = e["rescored_ms"].get<double>();
        if (e["ms"].get<double>() < optimum) optimum = e["ms"].get<double>(), rescored = e["rescored_ms"].get<double>();
    }
    EXPECT_DOUBLE_EQ(ex["best_table_ms"].get<double>(), optimum);
    EXPECT_DOUBLE_EQ(ex["best_ms"].get<double>(), rescored);
    EXPECT_DOUBLE_EQ(ex["equal_budget"]["optimum_ms"].get<double>(), rescored);
    // The tuner's own choice, re-measured too (not its measurement while tuning).
    json tuned = json::object();
    tuned["density"] = st.candidates[st.best_candidate].params["density"];
    EXPECT_DOUBLE_EQ(ex["tuned_ms"].get<double>(), second.at(tuned.dump()));
    const json& seeds = ex["search_on_measured_surface"];
    ASSERT_EQ(seeds.size(), 5u);
    for (std::size_t i = 0; i < seeds.size(); ++i) {
        EXPECT_EQ(seeds[i]["seed"], 7 + i);  // the file's seed and the four after it
        EXPECT_LE(seeds[i]["evaluations"].get<std::size_t>(), 3u);
        const double scored = second.at(seeds[i]["best_params"].dump());
        EXPECT_DOUBLE_EQ(seeds[i]["scored_ms"].get<double>(), scored);
        EXPECT_NEAR(seeds[i]["gap"].get<double>(), scored / rescored - 1, 1e-12);
    }
    const double rho = ex["prediction_spearman"].get<double>();
    EXPECT_GE(rho, -1.0);
    EXPECT_LE(rho, 1.0);
    EXPECT_FALSE(ex["prediction_model"].get<std::string>().empty());  // calibrated although the mode is measured
}

/// A replay built by hand: one scene per entry of `updates_ns`, each frame with 100 rays of
/// `steps` traversal steps each; `tag` is what it counted (equal tags: one structure in effect).
CountingReplay made_replay(const std::vector<std::vector<double>>& updates_ns, double steps, std::uint64_t tag) {
    CountingReplay r;
    for (const std::vector<double>& scene : updates_ns) {
        std::vector<CountingReplay::Frame>& frames = r.scenes.emplace_back();
        for (double update : scene) {
            CountingReplay::Frame f;
            f.update_ns = update;
            f.rays = 100;
            f.observation.rays = 100;
            f.observation.n_t = steps;
            frames.push_back(f);
        }
    }
    r.counts.counters.n_t = tag;
    r.counts.memory_bytes = 64 * tag;
    return r;
}

TEST(TunerExhaustiveCheck, OneReplayPerConfigurationPricesAndMergesIt) {
    // Five configurations of x; x = 1 and 2 count alike (one structure in effect), as do 3 and 4.
    std::vector<json> all;
    for (int x = 0; x < 5; ++x) all.push_back({{"x", x}});
    const auto replay_of = [](const json& p) {
        const int x = p["x"].get<int>();
        return made_replay({{1000.0 * (x + 1), 3000, 2000}, {500, 500}}, 2.0 * x, std::uint64_t((x + 1) / 2));
    };
    std::map<std::string, int> calls;
    const auto counted = [&](const json& p) {
        ++calls[p.dump()];
        return replay_of(p);
    };
    CostCoefficients c;
    c["C_T"] = 5;      // ns per traversal step
    c["C_PREP"] = 20;  // ns per ray
    const SpaceSurvey survey = survey_space(all, c, counted);
    ASSERT_EQ(calls.size(), all.size());
    for (const auto& [p, n] : calls) EXPECT_EQ(n, 1) << p;
    EXPECT_EQ(survey.class_of, (std::vector<std::size_t>{0, 1, 1, 2, 2}));
    ASSERT_EQ(survey.predicted.size(), all.size());
    for (std::size_t i = 0; i < all.size(); ++i) {
        // Per frame update + 100 rays × (20 + 5 × steps) ns; the median of scene 0's three frames
        // (the update 1000·(x+1) sorts among 2000 and 3000), then the mean with scene 1's.
        const double x = double(i), rays_ns = 100 * (20 + 5 * 2.0 * x);
        const double median0 = std::clamp(1000 * (x + 1), 2000.0, 3000.0) + rays_ns;
        EXPECT_NEAR(survey.predicted[i], (median0 + 500 + rays_ns) / 2 / 1e6, 1e-15) << i;
        // The old path, a replay for the prediction and another for the counts, agrees.
        EXPECT_DOUBLE_EQ(survey.predicted[i], replay_cost(c, replay_of(all[i]))) << i;
    }
    std::vector<ReplayCounts> counts;
    for (const json& p : all) counts.push_back(replay_of(p).counts);
    EXPECT_EQ(survey.class_of, equality_classes(counts, [](const auto& a, const auto& b) { return a == b; }));
}

TEST(TunerExhaustiveCheck, ARealSurveyReplaysEachConfigurationOnceAndMergesAsBefore) {
    // A hash grid of depth 0 ignores its capacity: two configurations, one structure in effect.
    const TuneCategory category{"u",
                                {test::generated_spec("u", "uniform", 1500, 3, 150, {{"survey", 1}}),
                                 test::generated_spec("v", "irregular", 800, 3, 150, {{"survey", 2}})}};
    const std::vector<json> all{{{"max_depth", 0}, {"max_capacity", 8}},
                                {{"max_depth", 0}, {"max_capacity", 32}},
                                {{"max_depth", 2}, {"max_capacity", 1}}};
    CostCoefficients c;
    c["C_T"] = 1e6;  // far above the replays' update times, which are measured
    const SimulationTally before = simulation_tally();
    const SpaceSurvey survey =
        survey_space(all, c, [&](const json& p) { return counting_replay(category, "hg", p, 1); });
    const SimulationTally after = simulation_tally();
    EXPECT_EQ(after.counting - before.counting, all.size() * category.scenes.size());
    EXPECT_EQ(after.timed, before.timed);
    // The classes the exhaustive check took from replays of their own (predict_cost's counts).
    std::vector<ReplayCounts> old(all.size());
    for (std::size_t i = 0; i < all.size(); ++i) predict_cost(CostCoefficients{}, category, "hg", all[i], 1, &old[i]);
    EXPECT_EQ(survey.class_of, equality_classes(old, [](const auto& a, const auto& b) { return a == b; }));
    EXPECT_EQ(survey.class_of, (std::vector<std::size_t>{0, 0, 1}));
    // The prediction as predict_cost makes it: equal up to the replays' measured update times.
    for (std::size_t i = 0; i < all.size(); ++i) {
        const double again = predict_cost(c, category, "hg", all[i], 1);
        EXPECT_NEAR(survey.predicted[i], again, 1e-3 * again) << i;
    }
}

}  // namespace
}  // namespace rcb

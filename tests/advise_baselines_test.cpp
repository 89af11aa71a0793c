// advise --exhaustive's budget-matched baselines on made-up cost tables: the random draw (seeded,
// uniform, within the budget; with replays, one per structure in effect), the model-free descent
// (from the category's parameters, only to measured improvements, stopped at the budget; with
// replays, past twins of what it measured) and the comparison that chooses every method on one
// table and scores it on a re-measurement; the pure-model choice, which must be what --verify-top 0
// advises; and advise's own steps taken on the table (advise-table).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <set>

#include "tuner/advise.h"
#include "tuner/advise_baselines.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// Two dimensions: "a" with levels 1..na, "b" with levels 1..nb.
std::vector<SearchDimension> grid_space(int na, int nb) {
    SearchDimension a{"a", {}}, b{"b", {}};
    for (int i = 1; i <= na; ++i) a.levels.push_back(i);
    for (int i = 1; i <= nb; ++i) b.levels.push_back(i);
    return {a, b};
}

/// The cost of every configuration of `space` by `f(a, b)`.
std::vector<double> table(const std::vector<json>& configurations, const std::function<double(int, int)>& f) {
    std::vector<double> costs;
    for (const json& p : configurations) costs.push_back(f(p["a"].get<int>(), p["b"].get<int>()));
    return costs;
}

/// A 4 x 4 space whose costs rise by 1 per level away from its best, a = 3 and b = 2 (cost 1);
/// the category's parameters at a = 1, b = 1.
MethodInputs bowl() {
    MethodInputs in;
    in.space = grid_space(4, 4);
    in.configurations = enumerate_space(in.space);
    in.table = table(in.configurations, [](int a, int b) { return 1.0 + std::abs(a - 3) + std::abs(b - 2); });
    in.category = {{"a", 1}, {"b", 1}};
    return in;
}

/// compare_methods with a scoring pass that reads `rescored` (per configuration), and the indices
/// it was asked for in `asked`.
MethodComparison scored_on(const MethodInputs& in, const std::vector<double>& rescored,
                           std::vector<std::size_t>* asked = nullptr) {
    int calls = 0;
    MethodComparison m = compare_methods(in, [&](const std::vector<std::size_t>& indices) {
        ++calls;
        if (asked) *asked = indices;
        std::vector<double> out;
        for (const std::size_t i : indices) out.push_back(rescored.at(i));
        return out;
    });
    EXPECT_EQ(calls, 1);  // one scoring pass, after every choice
    return m;
}

TEST(AdviseBaselines, RandomPicksAreSeededDistinctAndWithinTheBudget) {
    const std::vector<std::size_t> a = random_picks(40, 7, 11);
    EXPECT_EQ(a, random_picks(40, 7, 11));  // same seed, same picks
    EXPECT_NE(a, random_picks(40, 7, 12));
    ASSERT_EQ(a.size(), 7u);
    EXPECT_EQ(std::set<std::size_t>(a.begin(), a.end()).size(), 7u);  // without replacement
    for (const std::size_t i : a) EXPECT_LT(i, 40u);
    // A budget above the space takes the space once, never more.
    std::vector<std::size_t> all = random_picks(5, 9, 3);
    std::sort(all.begin(), all.end());
    EXPECT_EQ(all, (std::vector<std::size_t>{0, 1, 2, 3, 4}));
    EXPECT_TRUE(random_picks(5, 0, 3).empty());
}

TEST(AdviseBaselines, RandomPicksAreUniformOverTheSpace) {
    // 3 of 8 over 4000 seeds: each configuration is drawn 1500 times in expectation (sd ≈ 31).
    std::vector<int> drawn(8, 0);
    for (std::uint64_t seed = 1; seed <= 4000; ++seed)
        for (const std::size_t i : random_picks(8, 3, seed)) ++drawn[i];
    for (const int n : drawn) {
        EXPECT_GT(n, 1350);
        EXPECT_LT(n, 1650);
    }
}

TEST(AdviseBaselines, TheDescentStartsAtTheCategoryAndStopsAtTheBudget) {
    const std::vector<SearchDimension> space = grid_space(8, 1);
    const std::vector<json> configurations = enumerate_space(space);
    const std::vector<double> costs = table(configurations, [](int a, int) { return 10.0 - a; });  // falls with a
    const std::vector<std::size_t> path = descent_path(space, configurations, costs, json{{"a", 2}, {"b", 1}}, 3);
    ASSERT_EQ(path.size(), 3u);
    EXPECT_EQ(configurations[path[0]], (json{{"a", 2}, {"b", 1}}));
    EXPECT_EQ(configurations[path[1]], (json{{"a", 3}, {"b", 1}}));  // first improvement: one level up
    EXPECT_EQ(configurations[path[2]], (json{{"a", 4}, {"b", 1}}));
    // With the budget to spare it reaches the end of the line and stops there.
    const std::vector<std::size_t> longer = descent_path(space, configurations, costs, json{{"a", 2}, {"b", 1}}, 50);
    // a=2 … a=8, each one level up and faster; from a=8 no unmeasured neighbour is left.
    EXPECT_EQ(longer.size(), 7u);
    EXPECT_EQ(configurations[longer.back()]["a"], 8);
    EXPECT_TRUE(descent_path(space, configurations, costs, json{{"a", 2}, {"b", 1}}, 0).empty());
}

TEST(AdviseBaselines, TheDescentMovesOnlyToMeasuredImprovements) {
    const std::vector<SearchDimension> space = grid_space(6, 5);
    const std::vector<json> configurations = enumerate_space(space);
    // A bumpy surface: a bump at a=3 hides the valley at a=4..5 from one-level steps.
    const std::vector<double> costs = table(configurations, [](int a, int b) {
        const double along_a[] = {5, 4, 9, 3, 1, 8};
        return along_a[a - 1] + 0.5 * std::abs(b - 4);
    });
    const std::vector<std::size_t> path = descent_path(space, configurations, costs, json{{"a", 2}, {"b", 1}}, 30);
    ASSERT_FALSE(path.empty());
    EXPECT_EQ(configurations[path[0]], (json{{"a", 2}, {"b", 1}}));
    EXPECT_EQ(std::set<std::size_t>(path.begin(), path.end()).size(), path.size());  // each measured once
    // Replaying the path: every configuration it measures is a neighbour (one or two levels in one
    // parameter) of the fastest measured before it, which it replaces only when faster.
    std::size_t current = path[0];
    for (std::size_t k = 1; k < path.size(); ++k) {
        const json& from = configurations[current];
        const json& to = configurations[path[k]];
        const int da = std::abs(to["a"].get<int>() - from["a"].get<int>());
        const int db = std::abs(to["b"].get<int>() - from["b"].get<int>());
        EXPECT_TRUE((da == 0) != (db == 0) && std::max(da, db) <= 2) << from << " -> " << to;
        if (costs[path[k]] < costs[current]) current = path[k];
    }
    // It crossed the bump (two levels where one found nothing) and found the valley floor.
    EXPECT_EQ(configurations[current], (json{{"a", 5}, {"b", 4}}));
    // A start missing a level starts at the middle one, as the search does.
    EXPECT_EQ(configurations[descent_path(space, configurations, costs, json{{"a", 2}}, 1)[0]],
              (json{{"a", 2}, {"b", 3}}));
}

TEST(AdviseBaselines, EveryMethodIsChosenOnTheTableAndScoredOnOneRemeasurement) {
    MethodInputs in = bowl();
    in.advised = {{"a", 3}, {"b", 3}};
    in.predicted_best = json{{"a", 4}, {"b", 2}};
    in.budget = 5;
    in.seed = 7;
    std::vector<std::size_t> asked;
    const MethodComparison c = scored_on(in, in.table, &asked);
    const std::vector<MethodOutcome>& m = c.methods;
    ASSERT_EQ(m.size(), 5u);
    // The scoring pass re-measures the table's best first, then each choice once, nothing else.
    ASSERT_FALSE(asked.empty());
    EXPECT_EQ(in.configurations[asked[0]], (json{{"a", 3}, {"b", 2}}));
    EXPECT_EQ(std::set<std::size_t>(asked.begin(), asked.end()).size(), asked.size());
    for (const MethodOutcome& o : m) EXPECT_NE(std::find(asked.begin(), asked.end(), o.index), asked.end());
    EXPECT_LE(asked.size(), m.size() + 1);
    EXPECT_EQ(m[0].method, "advise");
    EXPECT_EQ(m[0].timed, 5u);
    EXPECT_DOUBLE_EQ(m[0].ms, 2.0);
    EXPECT_DOUBLE_EQ(m[0].regret, 1.0);  // the best costs 1
    EXPECT_EQ(m[1].method, "model");
    EXPECT_EQ(m[1].searched, (json{{"a", 4}, {"b", 2}}));
    EXPECT_DOUBLE_EQ(m[1].regret, 1.0);
    EXPECT_EQ(m[2].method, "category");
    EXPECT_DOUBLE_EQ(m[2].ms, 4.0);
    EXPECT_EQ(m[3].method, "random");
    EXPECT_EQ(m[3].timed, 5u);
    double best_drawn = INFINITY;
    for (const std::size_t i : random_picks(16, 5, 7)) best_drawn = std::min(best_drawn, in.table[i]);
    EXPECT_DOUBLE_EQ(m[3].ms, best_drawn);
    EXPECT_EQ(m[4].method, "descent");
    EXPECT_LE(m[4].timed, 5u);
    EXPECT_DOUBLE_EQ(m[4].regret, m[4].ms - 1.0);
    // Without a model (the category method) there is no pure-model row.
    in.predicted_best.reset();
    EXPECT_EQ(scored_on(in, in.table).methods.size(), 4u);
}

TEST(AdviseBaselines, ALuckyOptimumInTheTableIsScoredOnItsRemeasurement) {
    // The winner's curse: one configuration looks fastest in the table by noise, so the table
    // calls it the optimum and random search, timing every configuration, picks it. Scored on the
    // table, random would have regret 0 and advise, at the true best, +100%. Scored on the
    // re-measurement, the lucky draw costs what it does and advise's choice is the better one.
    MethodInputs in = bowl();
    const std::vector<double> truth = in.table;
    in.advised = {{"a", 3}, {"b", 2}};  // the true best, cost 1
    in.budget = 16;                     // random times every configuration
    in.seed = 3;
    std::size_t decoy = 0;
    while (in.configurations[decoy] != json{{"a", 1}, {"b", 4}}) ++decoy;
    in.table[decoy] = 0.5;  // truly 5, in the table's eyes only faster than the best
    const MethodComparison c = scored_on(in, truth);
    EXPECT_EQ(c.optimum, decoy);  // the optimum is the table's best, never the re-measurement's
    EXPECT_DOUBLE_EQ(c.optimum_table_ms, 0.5);
    EXPECT_DOUBLE_EQ(c.optimum_ms, 5.0);
    const std::vector<MethodOutcome>& m = c.methods;
    ASSERT_EQ(m.size(), 4u);
    EXPECT_EQ(m[0].method, "advise");
    EXPECT_DOUBLE_EQ(m[0].table_ms, 1.0);
    EXPECT_DOUBLE_EQ(m[0].ms, 1.0);
    EXPECT_DOUBLE_EQ(m[0].regret, 1.0 / 5.0 - 1);  // not 1.0 / 0.5 - 1: the lucky draw is not the yardstick
    EXPECT_EQ(m[2].method, "random");
    EXPECT_EQ(m[2].searched, (json{{"a", 1}, {"b", 4}}));
    EXPECT_DOUBLE_EQ(m[2].table_ms, 0.5);
    EXPECT_DOUBLE_EQ(m[2].ms, 5.0);  // scored on the re-measurement
    EXPECT_DOUBLE_EQ(m[2].regret, 0.0);
    EXPECT_LT(m[0].regret, m[2].regret);  // on the table's numbers random would have won
}

TEST(AdviseBaselines, TheBaselinesGetAdvisesReplaysAndSkipTwinsWithThem) {
    // Pairs of configurations that count alike (b = 1 and b = 2, b = 3 and b = 4): one structure
    // in effect each. With replays, random times one of each pair it draws and the descent passes
    // a twin of what it timed; both report the replays they spent.
    MethodInputs in = bowl();
    in.advised = {{"a", 3}, {"b", 2}};
    in.budget = 4;
    in.seed = 5;
    for (const json& p : in.configurations)
        in.class_of.push_back(std::size_t(p["a"].get<int>() - 1) * 2 + std::size_t(p["b"].get<int>() - 1) / 2);
    in.replays = 16;
    const std::vector<std::size_t> picks = random_timed(16, in.budget, in.replays, in.class_of, in.seed);
    ASSERT_EQ(picks.size(), 4u);
    std::set<std::size_t> classes;
    for (const std::size_t i : picks) classes.insert(in.class_of[i]);
    EXPECT_EQ(classes.size(), picks.size());  // no structure timed twice
    // Without replays: the first four drawn, twins or not.
    EXPECT_EQ(random_timed(16, 4, 0, in.class_of, in.seed), random_picks(16, 4, in.seed));
    std::size_t replayed = 0;
    const std::vector<std::size_t> path =
        descent_path(in.space, in.configurations, in.table, in.category, 8, in.class_of, 3, &replayed);
    EXPECT_EQ(replayed, 3u);  // at most the replays given
    std::set<std::size_t> timed_classes;
    for (std::size_t k = 0; k < path.size() && k < 3; ++k) timed_classes.insert(in.class_of[path[k]]);
    EXPECT_EQ(timed_classes.size(), std::min<std::size_t>(3, path.size()));
    const MethodComparison c = scored_on(in, in.table);
    ASSERT_EQ(c.methods.size(), 4u);
    EXPECT_EQ(c.methods[0].replays, 16u);  // advise
    EXPECT_EQ(c.methods[1].method, "category");
    EXPECT_EQ(c.methods[1].replays, 0u);
    EXPECT_EQ(c.methods[2].method, "random");
    EXPECT_EQ(c.methods[2].replays, 16u);
    EXPECT_EQ(c.methods[2].timed, 4u);
    EXPECT_EQ(c.methods[3].method, "descent");
    EXPECT_LE(c.methods[3].replays, 16u);
    EXPECT_LE(c.methods[3].timed, 4u);
}

/// A ranking of "a" = 1..5 (b = 1) with these predictions, each level counting differently.
ModelRanking ranking_of(const std::vector<double>& predicted) {
    ModelRanking r;
    for (int a = 1; a <= int(predicted.size()); ++a) {
        r.search.evaluations.push_back({json{{"a", a}, {"b", 1}}, predicted[std::size_t(a - 1)]});
        ReplayCounts counts;
        counts.counters.n_t = std::uint64_t(a);
        r.replays.entries.push_back({json{{"a", a}, {"b", 1}}, counts});
    }
    return r;
}

TEST(AdviseBaselines, ThePureModelChoiceIsWhatVerifyTopZeroAdvises) {
    // Rankings with ties and with the best prediction evaluated late: the pure-model choice of
    // advise (the first by prediction_order) is what verify_candidates with verify_top 0, then
    // order_candidates, put first; and it measures nothing to get there.
    const std::vector<SearchDimension> space = grid_space(5, 1);
    const std::vector<std::vector<double>> predictions{{3, 1, 2, 1, 5}, {5, 4, 3, 2, 1}, {2, 2, 2, 2, 2}};
    for (const std::vector<double>& predicted : predictions) {
        const ModelRanking r = ranking_of(predicted);
        const json pure = r.search.evaluations[prediction_order(r.search.evaluations).front()].params;
        int measured = 0;
        ModelEvidence e = verify_candidates(r, space, json{{"a", 3}, {"b", 1}}, 0, [&](const json& p) {
            ++measured;
            MeasuredCost c;
            c.ms = 10.0 - p["a"].get<double>();  // the measurement disagrees with the model
            return c;
        });
        order_candidates(e.candidates, AccuracyConstraint{});
        EXPECT_EQ(e.candidates.front().searched, pure);
        EXPECT_EQ(measured, 0);
        EXPECT_TRUE(std::none_of(e.candidates.begin(), e.candidates.end(),
                                 [](const ModelCandidate& c) { return c.measured.has_value(); }));
    }
}

/// A table of MeasuredCost over `configurations` by "a".
std::vector<MeasuredCost> measured_table(const std::vector<json>& configurations, const std::vector<double>& by_a) {
    std::vector<MeasuredCost> out;
    for (const json& p : configurations) {
        MeasuredCost c;
        c.ms = by_a[std::size_t(p["a"].get<int>() - 1)];
        out.push_back(c);
    }
    return out;
}

TEST(AdviseBaselines, AdviseOnTheTableTakesItsOwnStepsOnTheTablesNumbers) {
    const std::vector<SearchDimension> space = grid_space(5, 1);
    const std::vector<json> configurations = enumerate_space(space);
    const ModelRanking r = ranking_of({4, 1, 3, 2, 5});  // the model ranks a = 2 first
    const DescentSettings settings{space, json{{"a", 1}, {"b", 1}}, 6, AccuracyConstraint{}};
    int replays = 0;
    const ReplayPrediction predict = [&](const json&, ReplayCounts&) { return double(++replays); };
    // Table: the optimum at a = 3, one level above the model's best. advise verifies a = 2 and the
    // category's a = 1, then descends to a = 3 and finds nothing faster one or two levels away.
    std::optional<TableChoice> c =
        advise_on_table(r, settings, 1, configurations, measured_table(configurations, {5, 3, 2, 4, 6}), predict);
    ASSERT_TRUE(c);
    EXPECT_EQ(c->searched, (json{{"a", 3}, {"b", 1}}));
    EXPECT_EQ(c->timed, 5u);  // a = 2, 1, 3, 4, 5: each read once
    EXPECT_EQ(replays, 0);    // every level was replayed by the ranking already
    // The same steps on another table choose by its numbers: here the model's best stands.
    c = advise_on_table(r, settings, 1, configurations, measured_table(configurations, {5, 1, 2, 4, 6}), predict);
    ASSERT_TRUE(c);
    EXPECT_EQ(c->searched, (json{{"a", 2}, {"b", 1}}));
    EXPECT_EQ(c->timed, 4u);  // a = 2, 1, 3, then 4 (two levels up); 0 does not exist
    // Without refinement the two verified are all it reads.
    c = advise_on_table(r, {space, json{{"a", 1}, {"b", 1}}, 0, AccuracyConstraint{}}, 1, configurations,
                        measured_table(configurations, {5, 3, 2, 4, 6}), predict);
    ASSERT_TRUE(c);
    EXPECT_EQ(c->searched, (json{{"a", 2}, {"b", 1}}));
    EXPECT_EQ(c->timed, 2u);
    // A category level the table lacks cannot be priced: no choice.
    EXPECT_FALSE(advise_on_table(r, {space, json{{"a", 9}, {"b", 1}}, 6, AccuracyConstraint{}}, 1, configurations,
                                 measured_table(configurations, {5, 3, 2, 4, 6}), predict));
}

TEST(AdviseBaselines, AdviseOnTheTableIsScoredBesideAdvise) {
    MethodInputs in = bowl();
    in.advised = {{"a", 1}, {"b", 1}};
    in.advised_on_table = TableChoice{json{{"a", 3}, {"b", 3}}, 4, 7};
    in.budget = 5;
    const MethodComparison c = scored_on(in, in.table);
    const std::vector<MethodOutcome>& m = c.methods;
    ASSERT_EQ(m.size(), 5u);  // advise, advise-table, category, random, descent
    EXPECT_EQ(m[0].method, "advise");
    EXPECT_DOUBLE_EQ(m[0].regret, 3.0);
    EXPECT_EQ(m[1].method, "advise-table");
    EXPECT_EQ(m[1].timed, 4u);
    EXPECT_EQ(m[1].replays, 7u);
    EXPECT_EQ(m[1].searched, (json{{"a", 3}, {"b", 3}}));
    EXPECT_DOUBLE_EQ(m[1].ms, 2.0);
    EXPECT_DOUBLE_EQ(m[1].regret, 1.0);
    EXPECT_EQ(m[2].method, "category");
}

}  // namespace
}  // namespace rcb

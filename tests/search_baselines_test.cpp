// The baselines a search is judged against at equal budgets (tuner/search_baselines.h): random
// search's exact expectation, the model-free descent from the defaults, the merging of configurations that
// are one structure in effect, and the summary over problems.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

#include "tuner/search_baselines.h"

namespace rcb {
namespace {

std::vector<nlohmann::json> levels(int n) {
    std::vector<nlohmann::json> out;
    for (int i = 0; i < n; ++i) out.push_back(i);
    return out;
}

/// The mean over every k-subset of the lowest cost: the expectation by enumeration.
double enumerated_best_of(const std::vector<double>& costs, std::size_t k) {
    const std::size_t n = costs.size();
    double sum = 0;
    std::size_t subsets = 0;
    for (std::uint32_t mask = 0; mask < (1u << n); ++mask) {
        if (std::size_t(__builtin_popcount(mask)) != k) continue;
        double best = INFINITY;
        for (std::size_t i = 0; i < n; ++i)
            if (mask & (1u << i)) best = std::min(best, costs[i]);
        sum += best, ++subsets;
    }
    return sum / double(subsets);
}

TEST(SearchBaselines, RandomSearchsExpectationIsExact) {
    EXPECT_DOUBLE_EQ(expected_best_of_random({4, 2, 3, 1}, 1), 2.5);
    EXPECT_DOUBLE_EQ(expected_best_of_random({4, 2, 3, 1}, 4), 1.0);
    EXPECT_NEAR(expected_best_of_random({4, 2, 3, 1}, 2), 10.0 / 6.0, 1e-12);
    const std::vector<double> costs = {3.5, 0.7, 9.1, 2.2, 2.2, 5.0, 1.3, 8.8, 0.9};
    for (std::size_t k = 1; k <= costs.size(); ++k)
        EXPECT_NEAR(expected_best_of_random(costs, k), enumerated_best_of(costs, k), 1e-12) << "k " << k;
    EXPECT_DOUBLE_EQ(expected_best_of_random({5, 1}, 99), 1.0);  // k clamped to n
    EXPECT_TRUE(std::isnan(expected_best_of_random({}, 3)));
    // An unusable configuration only matters when it can be the best drawn.
    EXPECT_DOUBLE_EQ(expected_best_of_random({1, INFINITY}, 2), 1.0);
    EXPECT_TRUE(std::isinf(expected_best_of_random({1, INFINITY}, 1)));
}

TEST(SearchBaselines, EqualCountsAreOneStructureInEffect) {
    const std::vector<int> counts = {5, 7, 5, 9, 7, 5};
    EXPECT_EQ(equality_classes(counts, [](int a, int b) { return a == b; }),
              (std::vector<std::size_t>{0, 1, 0, 2, 1, 0}));
}

TEST(SearchBaselines, TheComparisonMergesClassesAndPricesEveryMethodOnOneSurface) {
    // 10 × 4 configurations; `b` changes nothing (one structure in effect per level of `a`), and
    // the measurements of one class differ only by noise.
    const std::vector<SearchDimension> dims = {{"a", levels(10)}, {"b", levels(4)}};
    const std::vector<nlohmann::json> all = enumerate_space(dims);
    std::vector<double> costs;
    std::vector<std::size_t> class_of;
    for (const nlohmann::json& p : all) {
        const int a = p["a"].get<int>(), b = p["b"].get<int>();
        costs.push_back(1.0 + 0.1 * std::abs(a - 8) + 0.001 * b);
        class_of.push_back(std::size_t(a));
    }
    // A model that ranks a = 7 first (and has a NaN it must never choose).
    std::vector<double> predicted;
    for (const nlohmann::json& p : all) predicted.push_back(p["a"] == 0 ? NAN : std::abs(p["a"].get<int>() - 7.0));
    const BudgetComparison c =
        compare_at_equal_budget(dims, all, costs, class_of, {{"a", 2}, {"b", 0}}, 0.3, 1, 5, predicted, 6);
    EXPECT_EQ(c.configurations, 40u);
    EXPECT_EQ(c.classes, 10u);
    EXPECT_EQ(c.budget, 3u);
    EXPECT_NEAR(c.optimum, 1.0015, 1e-12);  // class a = 8: the median of 1.000 … 1.003
    EXPECT_EQ(c.tuner_regrets.size(), 5u);
    std::vector<double> class_cost;
    for (int a = 0; a < 10; ++a) class_cost.push_back(1.0015 + 0.1 * std::abs(a - 8));
    EXPECT_NEAR(c.random_regret, expected_best_of_random(class_cost, 3) / 1.0015 - 1, 1e-12);
    // Three measurements of the descent from a = 2: a = 3, then a = 4, each faster (first improvement).
    EXPECT_NEAR(c.descent_regret, class_cost[4] / 1.0015 - 1, 1e-12);
    for (double r : c.tuner_regrets) EXPECT_GE(r, 0);
    // The model's choice is priced at its class's cost, with the timed runs it was given.
    EXPECT_NEAR(c.model_regret, class_cost[7] / 1.0015 - 1, 1e-12);
    EXPECT_EQ(c.model_timed, 6u);
    // Without a prediction there is no model row.
    EXPECT_TRUE(
        std::isnan(compare_at_equal_budget(dims, all, costs, class_of, {{"a", 2}, {"b", 0}}, 0.3, 1, 1).model_regret));
}

TEST(SearchBaselines, RegretIsScoredOnASecondTableNotTheOneChosenFrom) {
    // One level of `a`, the table's optimum, is a lucky draw there: 0.5, truly 1.6. Every method
    // that finds it would score regret 0 on the table (and so beat random by construction); on the
    // second table the optimum costs what it does, and each choice is priced there too.
    const std::vector<SearchDimension> dims = {{"a", levels(6)}};
    const std::vector<nlohmann::json> all = enumerate_space(dims);
    std::vector<double> truth, table;
    std::vector<std::size_t> class_of;
    for (const nlohmann::json& p : all) {
        const int a = p["a"].get<int>();
        truth.push_back(1.0 + 0.2 * std::abs(a - 2));  // truly best at a = 2
        class_of.push_back(std::size_t(a));
    }
    table = truth;
    table[5] = 0.5;                                   // a = 5: truly 1.6
    std::vector<double> predicted{5, 4, 3, 2, 1, 0};  // a model that ranks a = 5 first
    const BudgetComparison c =
        compare_at_equal_budget(dims, all, table, class_of, {{"a", 0}}, 0.5, 1, 1, predicted, 0, nullptr, truth);
    EXPECT_DOUBLE_EQ(c.optimum_table, 0.5);
    EXPECT_DOUBLE_EQ(c.optimum, 1.6);         // the optimum's re-measurement
    EXPECT_NEAR(c.model_regret, 0.0, 1e-12);  // it chose the table's optimum: no better, no worse
    // Random's expectation weighs each class by its chance of being the table's fastest drawn,
    // and takes its re-measured cost.
    std::vector<double> class_table(table.begin(), table.end()), class_truth(truth.begin(), truth.end());
    EXPECT_NEAR(c.random_regret, expected_score_of_random(class_table, class_truth, c.budget) / 1.6 - 1, 1e-12);
    // The descent from a = 0 walks down to a = 2 (truly the best) and is scored below 0 against
    // the lucky optimum; on the table it would have scored 1.0 / 0.5 - 1 = +100%.
    EXPECT_NEAR(c.descent_regret, 1.0 / 1.6 - 1, 1e-12);
    // Scored on the table itself (no second table), the same choices keep the curse.
    const BudgetComparison cursed =
        compare_at_equal_budget(dims, all, table, class_of, {{"a", 0}}, 0.5, 1, 1, predicted, 0, nullptr);
    EXPECT_NEAR(cursed.descent_regret, 1.0 / 0.5 - 1, 1e-12);
}

TEST(SearchBaselines, TheExpectedScoreOfRandomWeighsTheTablesOrder) {
    // k = 1: every configuration equally likely, the mean score; k = n: the table's best's score.
    EXPECT_DOUBLE_EQ(expected_score_of_random({3, 1, 2}, {30, 10, 20}, 1), 20.0);
    EXPECT_DOUBLE_EQ(expected_score_of_random({3, 1, 2}, {30, 7, 20}, 3), 7.0);
    // k = 2 of 3: the table's best is drawn with probability 2/3, the second best otherwise.
    EXPECT_NEAR(expected_score_of_random({3, 1, 2}, {30, 10, 20}, 2), 2.0 / 3 * 10 + 1.0 / 3 * 20, 1e-12);
    EXPECT_DOUBLE_EQ(expected_score_of_random({4, 2, 3, 1}, {4, 2, 3, 1}, 2), expected_best_of_random({4, 2, 3, 1}, 2));
}

TEST(SearchBaselines, TheSummaryCountsWinsAndQuantiles) {
    std::vector<BudgetComparison> problems(4);
    const double tuner[] = {0.0, 0.01, 0.05, 0.02}, random[] = {0.1, 0.01, 0.2, 0.3}, descent[] = {0, 0, 0.1, 0.5};
    for (std::size_t i = 0; i < 4; ++i) {
        problems[i].tuner_regret = tuner[i], problems[i].random_regret = random[i];
        problems[i].descent_regret = descent[i], problems[i].budget = 2, problems[i].classes = 20;
    }
    const SuiteSummary s = summarize_suite(problems);
    EXPECT_EQ(s.problems, 4u);
    EXPECT_DOUBLE_EQ(s.beats_random, 0.75);     // the tie at 1% is not a win
    EXPECT_DOUBLE_EQ(s.matches_descent, 0.75);  // 1% > 0% loses
    EXPECT_NEAR(s.tuner_median, 0.015, 1e-12);
    EXPECT_DOUBLE_EQ(s.median_budget_share, 0.1);
    EXPECT_EQ(s.model_problems, 0u);  // no problem priced a model
    EXPECT_TRUE(std::isnan(s.model_median));
    problems[1].model_regret = 0.04, problems[3].model_regret = 0.0;
    const SuiteSummary m = summarize_suite(problems);
    EXPECT_EQ(m.model_problems, 2u);
    EXPECT_NEAR(m.model_median, 0.02, 1e-12);
}

}  // namespace
}  // namespace rcb

// A cell's median over its repetitions with a 95% interval between repetitions: the t quantile,
// the interval from known values, its edge cases, that it narrows as repetitions are added, and
// that the interval the runner states covers the true value 95% of the time.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "core/base/random.h"
#include "core/base/statistics.h"
#include "runner/run_experiment.h"

namespace rcb {
namespace {

TEST(RepetitionInterval, StudentsTQuantileFromTheTableAndTheExpansion) {
    EXPECT_EQ(student_t_975(1), 12.706205);
    EXPECT_EQ(student_t_975(2), 4.302653);
    EXPECT_EQ(student_t_975(30), 2.042272);
    // Beyond the table, A&S 26.7.5 against the exact quantiles (to 6 decimals).
    EXPECT_NEAR(student_t_975(31), 2.039513, 1e-6);
    EXPECT_NEAR(student_t_975(64), 1.997730, 1e-6);
    EXPECT_NEAR(student_t_975(100), 1.983972, 1e-6);
    EXPECT_NEAR(student_t_975(1000000), 1.959966, 1e-6);
    EXPECT_TRUE(std::isinf(student_t_975(0)));
}

TEST(RepetitionInterval, TIntervalOnTheLogsFromKnownValues) {
    // 100 and 121: the logs' mean is ln 110 and s/√2 = ln(1.21)/2 = ln 1.1, so the interval is
    // 110 · 1.1^(±t(0.975, 1)); the median of two values is their mean.
    const RepetitionInterval two = repetition_interval({121, 100});
    EXPECT_EQ(two.repetitions, 2u);
    EXPECT_TRUE(two.has_interval());
    EXPECT_DOUBLE_EQ(two.median, 110.5);
    EXPECT_NEAR(two.low, 110 * std::pow(1.1, -12.706205), 1e-9);
    EXPECT_NEAR(two.high, 110 * std::pow(1.1, 12.706205), 1e-9);
    EXPECT_NEAR(two.relative_half_width(), (two.high - two.low) / 2 / 110.5, 1e-12);
    // 100, 110, 121: logs ln 110 ∓ ln 1.1, so s = ln 1.1 and the interval is 110 · 1.1^(±t(0.975, 2)/√3).
    const RepetitionInterval three = repetition_interval({110, 121, 100});
    EXPECT_DOUBLE_EQ(three.median, 110);
    EXPECT_NEAR(three.low, 110 * std::pow(1.1, -4.302653 / std::sqrt(3.0)), 1e-9);
    EXPECT_NEAR(three.high, 110 * std::pow(1.1, 4.302653 / std::sqrt(3.0)), 1e-9);
}

TEST(RepetitionInterval, EdgeCases) {
    // One repetition: no interval, infinitely wide for the rule that adds repetitions.
    const RepetitionInterval one = repetition_interval({7});
    EXPECT_FALSE(one.has_interval());
    EXPECT_EQ(one.median, 7);
    EXPECT_TRUE(std::isinf(one.relative_half_width()));
    EXPECT_EQ(repetition_interval({}).repetitions, 0u);
    // Equal values: a point.
    const RepetitionInterval same = repetition_interval({5, 5, 5});
    EXPECT_EQ(same.low, 5);
    EXPECT_EQ(same.high, 5);
    EXPECT_EQ(same.relative_half_width(), 0);
    // A value of 0: the t interval on the values themselves, mean 1 ± 12.706205 · √2 / √2.
    const RepetitionInterval zero = repetition_interval({0, 2});
    EXPECT_NEAR(zero.low, 1 - 12.706205, 1e-12);
    EXPECT_NEAR(zero.high, 1 + 12.706205, 1e-12);
    EXPECT_TRUE(std::isinf(repetition_interval({0, 0, 1}).relative_half_width()));  // median 0, not a point
}

TEST(RepetitionInterval, NarrowsAsRepetitionsGrow) {
    // A fixed sequence that keeps spreading 80..120: the interval's half-width still falls with
    // every repetition, from 193% at two to under 8% at sixteen.
    const std::vector<double> sequence = {80, 100, 120, 90, 110, 80, 100, 120, 90, 110, 80, 100, 120, 90, 110, 80};
    double last = INFINITY;
    for (std::size_t n = 2; n <= sequence.size(); ++n) {
        const double width = repetition_interval(std::vector<double>(sequence.begin(), sequence.begin() + long(n)))
                                 .relative_half_width();
        EXPECT_LT(width, last) << n;
        last = width;
    }
    EXPECT_GT(repetition_interval({80, 100}).relative_half_width(), 1.9);
    EXPECT_LT(last, 0.08);
}

/// A distribution a cell's repetition medians are drawn from, with its true median.
struct Source {
    std::string name;
    std::function<double(Random&)> draw;
    double median;
};

/// The median of a log-normal (median 1, log-spread `sigma`) scaled, with probability `p`, by
/// 1 + U(0.2, 1.0): a repetition that met another tenant of a shared host. Bisection on the CDF, the
/// slow part's integral over U by the midpoint rule.
double slow_outliers_median(double sigma, double p) {
    const auto phi = [](double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); };
    const auto cdf = [&](double x) {
        double slow = 0;
        constexpr int kSteps = 4000;
        for (int i = 0; i < kSteps; ++i) {
            const double u = 0.2 + 0.8 * (i + 0.5) / kSteps;
            slow += phi((std::log(x) - std::log(1 + u)) / sigma) / kSteps;
        }
        return (1 - p) * phi(std::log(x) / sigma) + p * slow;
    };
    double lo = 0.5, hi = 2;
    for (int i = 0; i < 60; ++i) (cdf(0.5 * (lo + hi)) < 0.5 ? lo : hi) = 0.5 * (lo + hi);
    return 0.5 * (lo + hi);
}

std::vector<Source> sources() {
    std::vector<Source> out;
    for (const double sigma : {0.01, 0.05, 0.2}) {
        out.push_back({"normal " + std::to_string(sigma), [sigma](Random& r) { return 1 + sigma * r.normal(); }, 1});
        out.push_back(
            {"log-normal " + std::to_string(sigma), [sigma](Random& r) { return std::exp(sigma * r.normal()); }, 1});
    }
    for (const double sigma : {0.01, 0.05}) {
        constexpr double kSlowShare = 0.1;
        out.push_back({"slow outliers " + std::to_string(sigma),
                       [sigma](Random& r) {
                           const double t = std::exp(sigma * r.normal());
                           return r.uniform() < kSlowShare ? t * (1 + r.uniform(0.2, 1.0)) : t;
                       },
                       slow_outliers_median(sigma, kSlowShare)});
    }
    return out;
}

/// Coverage of the true median over `trials` cells, each run as the runner runs one: `planned`
/// repetitions, then one more at a time while the interval over all so far is wider than ±5%
/// (wide_interval), up to `cap`. `stated`: the interval the store states (the planned ones');
/// otherwise the interval over every repetition, planned and added.
double coverage(const Source& s, std::size_t planned, std::size_t cap, bool stated, std::uint64_t seed) {
    constexpr int kTrials = 4000;
    Random r(seed);
    int covered = 0;
    for (int i = 0; i < kTrials; ++i) {
        std::vector<double> first, added;
        while (first.size() < planned) first.push_back(s.draw(r));
        std::vector<double> all = first;
        while (all.size() < cap && wide_interval(all, 0.05)) {
            added.push_back(s.draw(r));
            all.push_back(added.back());
        }
        const RepetitionInterval ci = stated ? repetition_interval(first, added) : repetition_interval(all);
        covered += ci.low <= s.median && s.median <= ci.high;
    }
    return double(covered) / kTrials;
}

TEST(RepetitionInterval, TheStatedIntervalCoversTheTrueMedianAtLeast93PercentOfTheTime) {
    // Repetition medians from known distributions: normal and log-normal at spreads of 1%, 5% and
    // 20%, and a log-normal where one repetition in ten met a busy host and ran 20–100% slow. The
    // stated interval rests on the planned repetitions, so adding repetitions where the interval is
    // wide (the runner's rule) cannot bend it. Seeded: the same fractions on every run.
    double worst_over_all = 1;
    std::uint64_t seed = 1;
    for (const Source& s : sources())
        for (const auto& [planned, cap] : {std::pair<std::size_t, std::size_t>{2, 4}, {3, 5}, {5, 8}}) {
            const double stated = coverage(s, planned, cap, true, seed);
            const double over_all = coverage(s, planned, cap, false, seed++);
            EXPECT_GE(stated, 0.93) << s.name << ", " << planned << " planned, at most " << cap;
            EXPECT_LE(stated, 0.985) << s.name << ", " << planned << " planned: a 95% interval much wider than one";
            worst_over_all = std::min(worst_over_all, over_all);
        }
    // An interval over the added repetitions too (optional stopping: a cell stops when two happen to
    // agree) does not keep its word somewhere: this is why the store leaves them out of it.
    EXPECT_LT(worst_over_all, 0.93);
}

}  // namespace
}  // namespace rcb

// A cell's median over its repetitions with a 95% interval between repetitions: the t quantile,
// the interval from known values, its edge cases, and that it narrows as repetitions are added.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/base/repetition_interval.h"

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

}  // namespace
}  // namespace rcb

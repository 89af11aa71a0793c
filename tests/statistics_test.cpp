// The one statistics header (core/base/statistics.h) against values worked by hand: the median of
// odd and even counts, quantiles linear between order statistics (p90 interpolated), infinite
// values, the order statistic without interpolation, the median's interval and MAD; and the
// formatting header's times (core/base/number_text.h).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "core/base/number_text.h"
#include "core/base/statistics.h"

namespace rcb {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(Statistics, MedianOfOddAndEvenCountsIsTheMiddleOrTheMeanOfTheTwoMiddleValues) {
    EXPECT_EQ(median({3, 1, 2}), 2.0);
    EXPECT_EQ(median({4, 1, 3, 2}), 2.5);  // (2 + 3) / 2
    EXPECT_EQ(median({7}), 7.0);
    EXPECT_EQ(median({1, 1000}), 500.5);
    EXPECT_TRUE(std::isnan(median({})));
}

TEST(Statistics, QuantileIsLinearBetweenOrderStatistics) {
    // Type 7: position q·(n − 1) in the sorted values, interpolated between its neighbours.
    const std::vector<double> four{4, 2, 1, 3};
    EXPECT_DOUBLE_EQ(quantile(four, 0.9), 3.7);  // position 2.7: 3 + 0.7·(4 − 3)
    EXPECT_DOUBLE_EQ(quantile(four, 0.5), 2.5);  // the even count's median
    EXPECT_DOUBLE_EQ(quantile(four, 0.1), 1.3);  // position 0.3
    EXPECT_EQ(quantile(four, 0.0), 1.0);
    EXPECT_EQ(quantile(four, 1.0), 4.0);
    const std::vector<double> five{50, 10, 40, 20, 30};
    EXPECT_DOUBLE_EQ(quantile(five, 0.9), 46.0);  // position 3.6: 40 + 0.6·10
    EXPECT_EQ(quantile(five, 0.5), 30.0);
    EXPECT_DOUBLE_EQ(quantile(five, 0.025), 11.0);  // position 0.1
    EXPECT_TRUE(std::isnan(quantile({}, 0.5)));
}

TEST(Statistics, AQuantileThatReachesAnInfiniteValueIsInfinite) {
    EXPECT_EQ(quantile({1, kInf}, 0.5), kInf);  // never inf − inf or 0·inf
    EXPECT_EQ(quantile({1, 2, kInf}, 0.5), 2.0);
    EXPECT_EQ(quantile({1, 2, kInf}, 0.9), kInf);
    EXPECT_EQ(quantile({kInf, kInf}, 0.3), kInf);
    EXPECT_EQ(quantile_or_nan({3, 1}, 0.5), 2.0);
    EXPECT_TRUE(std::isnan(quantile_or_nan({1, kInf, 2}, 0.5)));
    EXPECT_TRUE(std::isnan(quantile_or_nan({1, NAN}, 0.1)));
}

TEST(Statistics, OrderStatisticTakesTheLowerRankWithoutInterpolation) {
    const std::vector<double> sorted{1, 2, 3, 4};
    EXPECT_EQ(order_statistic(sorted, 0.9), 3.0);  // rank ⌊2.7⌋ = 2
    EXPECT_EQ(order_statistic(sorted, 0.5), 2.0);  // rank ⌊1.5⌋ = 1: one of the values, not 2.5
    EXPECT_EQ(order_statistic(sorted, 1.0), 4.0);
    EXPECT_EQ(order_statistic({}, 0.5), 0.0);
}

TEST(Statistics, SpreadHoldsTheMedianItsMadAndTheConoverInterval) {
    // 1..10: median 5.5; |x − 5.5| = 0.5, 0.5, 1.5, 1.5, 2.5, 2.5, 3.5, 3.5, 4.5, 4.5, MAD 2.5.
    // P(Binomial(10, ½) ≤ 1) = 11/1024 ≤ 2.5% < P(≤ 2) = 56/1024: k = 2, the interval x(2)..x(9).
    const Spread ten = spread_of({10, 9, 8, 7, 6, 5, 4, 3, 2, 1});
    EXPECT_EQ(ten.median, 5.5);
    EXPECT_EQ(ten.mad, 2.5);
    EXPECT_EQ(ten.ci_low, 2.0);
    EXPECT_EQ(ten.ci_high, 9.0);
    // Five values: no 95% interval exists, the range stands in; deviations 2, 1, 0, 1, 97: MAD 1.
    const Spread five = spread_of({100, 1, 2, 3, 4});
    EXPECT_EQ(five.median, 3.0);
    EXPECT_EQ(five.mad, 1.0);
    EXPECT_EQ(five.ci_low, 1.0);
    EXPECT_EQ(five.ci_high, 100.0);
    const Spread none = spread_of({});
    EXPECT_EQ(none.median, 0.0);
    EXPECT_EQ(none.ci_high, 0.0);
}

TEST(Statistics, TheRepetitionIntervalsMedianIsTheMedianOfAllValues) {
    const RepetitionInterval r = repetition_interval({4, 1}, {3, 2});
    EXPECT_EQ(r.median, 2.5);
    EXPECT_EQ(r.repetitions, 4u);
    EXPECT_EQ(r.planned, 2u);
}

TEST(NumberText, TimesNameTheirUnitAndKeepFourDecimalsWhenSmall) {
    EXPECT_EQ(format_ms(0.04213), "0.0421");  // below 0.1 ms: four decimals
    EXPECT_EQ(format_ms(0.1), "0.100");
    EXPECT_EQ(format_ms(12.5), "12.500");
    EXPECT_EQ(format_ms(NAN), "-");
    EXPECT_EQ(ms_decimals(0.099), 4);
    EXPECT_EQ(ms_decimals(0.1), 3);
    EXPECT_EQ(format_us(0.25), "0.2500");  // below 1 us: four decimals
    EXPECT_EQ(format_us(1.0), "1.000");
    EXPECT_EQ(format_us(kInf), "-");
    EXPECT_EQ(format_ms(12345.0 / 1e6), "0.0123");  // a time in ns, converted by the caller
}

}  // namespace
}  // namespace rcb

#pragma once
/// The order statistics and intervals every stage summarises with: the median, quantiles, a
/// median's distribution-free interval over frames, and a cell's interval over its repetitions.
/// Pure arithmetic on copies of the values; nothing here reads a clock or a database.
///
/// Quantiles are linear between order statistics (Hyndman and Fan, "Sample Quantiles in
/// Statistical Packages", 1996: type 7, R's and NumPy's default), as docs/model.md states. The
/// median of an even count is the mean of the two middle values, (x(n/2) + x(n/2+1)) / 2: the
/// same value as quantile(v, 0.5), computed the way the stored medians always were (the two
/// formulas can round differently in the last bit).

#include <cstddef>
#include <vector>

namespace rcb {

/// The median of `values`: the middle value, or the mean of the two middle ones; NaN when empty.
double median(std::vector<double> values);

/// The q-quantile (0..1) of `values`, linear between order statistics (type 7 above); NaN when
/// empty. An infinite value is larger than every finite one: a quantile that reaches it is
/// infinite.
double quantile(std::vector<double> values, double q);

/// quantile(values, q) when every value is finite, else NaN: a frame the model could not price
/// leaves its cell without a predicted median rather than with a biased one.
double quantile_or_nan(const std::vector<double>& values, double q);

/// The order statistic at rank ⌊q·(n−1)⌋ (0-based) of `sorted` (ascending), without interpolation;
/// 0 when empty. What the scene features and a scene's stored edge percentiles use (one of the
/// boxes' own sizes, never a size between two boxes).
double order_statistic(const std::vector<double>& sorted, double q);

/// Median and median absolute deviation of a series, and a distribution-free 95% interval of the
/// median: the order statistics x(k) and x(n+1-k) with the largest k for which a Binomial(n, 1/2)
/// falls below k with probability at most 2.5% (Conover, "Practical Nonparametric Statistics",
/// §3.2), narrowing as values are added. Below 6 values no such k exists: ci_low, ci_high are then
/// the range (least, greatest), not a 95% interval. Wide over frames that differ in work, not noise.
struct Spread {
    double median = 0;
    double mad = 0;
    double ci_low = 0, ci_high = 0;
};
/// All zero when `values` is empty.
Spread spread_of(std::vector<double> values);

/// A cell's time over its repetitions: the median of the per-repetition medians with a 95%
/// interval that reflects the spread between repetitions, not between frames. Frames within one
/// repetition run back to back and share the machine's state of that moment (the host's memory
/// system drifts over minutes), so an interval over frames is falsely narrow; the repetitions,
/// spread over the whole run, are the independent samples (Kalibera and Jones, "Rigorous
/// Benchmarking in Reasonable Time", ISMM 2013: the interval belongs at the level whose variation
/// dominates).
///
/// The interval is Student's t on the logarithms of the repetitions' medians, back-transformed:
/// exp(m ± t(0.975, n−1) · s / √n) with m and s the mean and standard deviation of the logs. Times
/// are positive and their drift multiplies, so the logs are the scale where it is symmetric. A
/// distribution-free interval of the median (the order statistics of Conover's §3.2, which the
/// frames' intervals use) reaches 95% only from 6 values: from 2 to 5 repetitions it is the whole
/// range, which covers the median with probability 1 − 2^(1−n), 50% at n = 2. The t interval is
/// honest at n = 2 (t = 12.71, wide) and narrows with n.
///
/// The interval rests on the repetitions planned before the run (the experiment's `repetitions`)
/// alone. The runner adds repetitions where the interval over those stored so far is wide; an
/// interval over them all would be optional stopping (a cell stops when two repetitions happen to
/// agree), which covers less than it states (tests/repetition_interval_test.cpp simulates both). The
/// added repetitions still count in the median, where more values only help.
///
/// Pure arithmetic: the runner decides with it which cells get another repetition, the store keeps
/// it per (run, scene, configuration).
struct RepetitionInterval {
    std::size_t repetitions = 0;  ///< every value: the planned ones and those added
    std::size_t planned = 0;      ///< the values the interval rests on
    double median = 0;            ///< of every value (0 when there are none)
    double low = 0, high = 0;     ///< the 95% interval; only meaningful from two planned values (has_interval)

    bool has_interval() const { return planned >= 2; }
    /// (high − low) / 2 / median: the interval's half-width as a fraction of the median. Infinite
    /// below two values (one repetition says nothing about the next) and where the median is 0 but
    /// the interval is not a point; 0 where every value is equal.
    double relative_half_width() const;
};

/// The 0.975 quantile of Student's t with `df` ≥ 1 degrees of freedom: a table to 30 (exact to the
/// 6 decimals shown), then the Cornish–Fisher expansion about the normal quantile (Abramowitz and
/// Stegun 26.7.5, four terms; within 1e-7 of the exact value from 30 on).
double student_t_975(std::size_t df);

/// The interval of the `planned` values (one median per repetition planned before the run), and the
/// median of those and the `added` ones together. Values must be finite. When a planned one is 0 or
/// negative (a made-up or empty phase), the t interval is taken on the values themselves instead of
/// their logs.
RepetitionInterval repetition_interval(const std::vector<double>& planned, const std::vector<double>& added = {});

}  // namespace rcb

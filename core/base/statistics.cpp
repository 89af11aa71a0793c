#include "core/base/statistics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

namespace rcb {
namespace {

/// The median of `sorted` (ascending, not empty).
double sorted_median(const std::vector<double>& sorted) {
    const std::size_t n = sorted.size();
    return n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
}

/// The 1-based rank k of the lower end of the 95% interval of a median of n values (Spread): the
/// largest k with P(Binomial(n, 1/2) <= k - 1) <= 0.025, at least 1.
std::size_t median_interval_rank(std::size_t n) {
    // P(B <= j) summed term by term in logs (n may be in the thousands).
    double cumulative = 0;
    std::size_t k = 1;
    for (std::size_t j = 0; j < n; ++j) {
        const double log_term = std::lgamma(double(n) + 1) - std::lgamma(double(j) + 1) -
                                std::lgamma(double(n - j) + 1) - double(n) * std::log(2.0);
        cumulative += std::exp(log_term);
        if (cumulative > 0.025) break;
        k = j + 1;  // P(B <= k - 1) <= 0.025: x(k) may be the lower end
    }
    return std::min(k, (n + 1) / 2);
}

}  // namespace

double median(std::vector<double> values) {
    if (values.empty()) return NAN;
    std::sort(values.begin(), values.end());
    return sorted_median(values);
}

double quantile(std::vector<double> values, double q) {
    if (values.empty()) return NAN;
    std::sort(values.begin(), values.end());
    const double at = q * double(values.size() - 1);
    const std::size_t lo = std::size_t(std::floor(at)), hi = std::min(lo + 1, values.size() - 1);
    // Infinite values (the validation's misses) order above every finite one: the quantile is
    // infinite where it reaches one, never inf − inf or 0·inf.
    const double t = at - double(lo);
    if (t == 0 || values[lo] == values[hi]) return values[lo];
    return std::isinf(values[hi]) ? values[hi] : values[lo] + t * (values[hi] - values[lo]);
}

double quantile_or_nan(const std::vector<double>& values, double q) {
    return std::all_of(values.begin(), values.end(), [](double x) { return std::isfinite(x); }) ? quantile(values, q)
                                                                                                : NAN;
}

double order_statistic(const std::vector<double>& sorted, double q) {
    return sorted.empty() ? 0.0 : sorted[std::size_t(q * double(sorted.size() - 1))];
}

Spread spread_of(std::vector<double> v) {
    if (v.empty()) return {};
    std::sort(v.begin(), v.end());
    Spread s;
    s.median = sorted_median(v);
    const std::size_t k = median_interval_rank(v.size());
    s.ci_low = v[k - 1];
    s.ci_high = v[v.size() - k];
    for (double& x : v) x = std::abs(x - s.median);
    std::sort(v.begin(), v.end());
    s.mad = sorted_median(v);
    return s;
}

double RepetitionInterval::relative_half_width() const {
    if (!has_interval()) return std::numeric_limits<double>::infinity();
    const double half = (high - low) / 2;
    if (half <= 0) return 0;
    return median > 0 ? half / median : std::numeric_limits<double>::infinity();
}

double student_t_975(std::size_t df) {
    // t(0.975, df) for df = 1..30, to 6 decimals.
    static constexpr std::array<double, 30> kTable = {
        12.706205, 4.302653, 3.182446, 2.776445, 2.570582, 2.446912, 2.364624, 2.306004, 2.262157, 2.228139,
        2.200985,  2.178813, 2.160369, 2.144787, 2.131450, 2.119905, 2.109816, 2.100922, 2.093024, 2.085963,
        2.079614,  2.073873, 2.068658, 2.063899, 2.059539, 2.055529, 2.051831, 2.048407, 2.045230, 2.042272};
    if (df == 0) return std::numeric_limits<double>::infinity();
    if (df <= kTable.size()) return kTable[df - 1];
    // Abramowitz and Stegun 26.7.5: t ≈ z + g1/ν + g2/ν² + g3/ν³ + g4/ν⁴, z the normal quantile.
    const double z = 1.959963984540054, v = double(df);
    const double z2 = z * z, z3 = z2 * z, z5 = z3 * z2, z7 = z5 * z2, z9 = z7 * z2;
    const double g1 = (z3 + z) / 4;
    const double g2 = (5 * z5 + 16 * z3 + 3 * z) / 96;
    const double g3 = (3 * z7 + 19 * z5 + 17 * z3 - 15 * z) / 384;
    const double g4 = (79 * z9 + 776 * z7 + 1482 * z5 - 1920 * z3 - 945 * z) / 92160;
    return z + g1 / v + g2 / (v * v) + g3 / (v * v * v) + g4 / (v * v * v * v);
}

RepetitionInterval repetition_interval(const std::vector<double>& planned, const std::vector<double>& added) {
    RepetitionInterval r;
    r.planned = planned.size();
    r.repetitions = planned.size() + added.size();
    if (r.repetitions == 0) return r;
    std::vector<double> all = planned;
    all.insert(all.end(), added.begin(), added.end());
    r.median = median(std::move(all));
    r.low = r.high = r.median;
    const std::size_t n = planned.size();
    if (n < 2) return r;
    const auto [lo, hi] = std::minmax_element(planned.begin(), planned.end());
    if (*lo == *hi) {
        r.low = r.high = *lo;
        return r;
    }
    const bool logs = *lo > 0;
    std::vector<double> x = planned;
    if (logs)
        for (double& v : x) v = std::log(v);
    double mean = 0;
    for (double v : x) mean += v;
    mean /= double(n);
    double squares = 0;
    for (double v : x) squares += (v - mean) * (v - mean);
    const double half = student_t_975(n - 1) * std::sqrt(squares / double(n - 1)) / std::sqrt(double(n));
    r.low = logs ? std::exp(mean - half) : mean - half;
    r.high = logs ? std::exp(mean + half) : mean + half;
    return r;
}

}  // namespace rcb

#include "analysis/statistics.h"

#include <algorithm>
#include <cmath>

namespace rcb {

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

}  // namespace rcb

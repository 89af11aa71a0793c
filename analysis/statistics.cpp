#include "analysis/statistics.h"

#include <algorithm>
#include <cmath>

namespace rcb {

double quantile(std::vector<double> values, double q) {
    if (values.empty()) return NAN;
    std::sort(values.begin(), values.end());
    const double at = q * double(values.size() - 1);
    const std::size_t lo = std::size_t(std::floor(at)), hi = std::min(lo + 1, values.size() - 1);
    return values[lo] + (at - double(lo)) * (values[hi] - values[lo]);
}

}  // namespace rcb

#pragma once
/// Order statistics the analysis stage shares (the noise floor, the validation's errors and
/// bootstrap intervals).

#include <vector>

namespace rcb {

/// The q-quantile (0..1) of `values` by linear interpolation between order statistics (Hyndman and
/// Fan's type 7, as R and NumPy default to); NaN when empty. An infinite value is larger than
/// every finite one: a quantile that reaches it is infinite.
double quantile(std::vector<double> values, double q);

}  // namespace rcb

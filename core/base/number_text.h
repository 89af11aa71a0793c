#pragma once
/// Numbers as text for tables, reports and tuning files.

#include <string>

namespace rcb {

/// Fixed-point with `digits` decimals.
std::string fixed(double value, int digits);
/// "1.2 MB", "340 KB", "512 B" (binary units).
std::string bytes_text(double bytes);

/// `value` rounded to `significant` decimal digits (12 by default), as the nearest double: what a
/// generated level (a range's from + i·step or from·times^k) should be, so that 0.125·√2^10 is 4,
/// the default 4.0, not 4.000000000000001 (a second configuration and a second cell key for one
/// structure in effect). Infinities and NaN come back as they are.
double decimal_rounded(double value, int significant = 12);

}  // namespace rcb

#pragma once
/// Numbers as text for tables, reports and tuning files. A time's function names its unit: the
/// caller converts to it (format_ms(ns / 1e6)), so no table mixes milliseconds and nanoseconds.

#include <string>

namespace rcb {

/// Fixed-point with `digits` decimals.
std::string fixed(double value, int digits);
/// A time in milliseconds, without the unit: four decimals below 0.1 ms, else three ("0.0421",
/// "1.250"), so a fast phase keeps its digits; "-" when not finite.
std::string format_ms(double ms);
/// The decimals format_ms gives `ms` (4 below 0.1 ms, else 3): for a range printed beside it.
int ms_decimals(double ms);
/// A time in microseconds, without the unit: four decimals below 1 us, else three; "-" when not
/// finite.
std::string format_us(double us);
/// "1.2 MB", "340 KB", "512 B" (binary units).
std::string bytes_text(double bytes);

/// `value` rounded to `significant` decimal digits (12 by default), as the nearest double: what a
/// generated level (a range's from + i·step or from·times^k) should be, so that 0.125·√2^10 is 4,
/// the default 4.0, not 4.000000000000001 (a second configuration and a second cell key for one
/// structure in effect). Infinities and NaN come back as they are.
double decimal_rounded(double value, int significant = 12);

}  // namespace rcb

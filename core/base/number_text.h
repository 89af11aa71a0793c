#pragma once
/// Numbers as text for tables, reports and tuning files.

#include <string>

namespace rcb {

/// Fixed-point with `digits` decimals.
std::string fixed(double value, int digits);
/// "1.2 MB", "340 KB", "512 B" (binary units).
std::string bytes_text(double bytes);

}  // namespace rcb

#include "core/base/number_text.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace rcb {

std::string fixed(double value, int digits) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(digits) << value;
    return s.str();
}

int ms_decimals(double ms) { return ms < 0.1 ? 4 : 3; }

std::string format_ms(double ms) { return std::isfinite(ms) ? fixed(ms, ms_decimals(ms)) : "-"; }

std::string format_us(double us) { return std::isfinite(us) ? fixed(us, us < 1 ? 4 : 3) : "-"; }

std::string bytes_text(double bytes) {
    const char* units[] = {"B", "KB", "MB", "GB", "TB"};
    int u = 0;
    while (bytes >= 1024 && u < 4) bytes /= 1024, ++u;
    return fixed(bytes, u == 0 ? 0 : 1) + " " + units[u];
}

double decimal_rounded(double value, int significant) {
    if (!std::isfinite(value) || value == 0) return value;
    significant = std::clamp(significant, 1, 17);
    // Through text: to_chars rounds to the digits, from_chars takes the nearest double (neither
    // depends on the locale).
    char text[64];
    const auto printed = std::to_chars(text, text + sizeof text, value, std::chars_format::scientific, significant - 1);
    double out = value;
    const auto parsed = std::from_chars(text, printed.ptr, out, std::chars_format::scientific);
    return parsed.ec == std::errc() ? out : value;
}

}  // namespace rcb

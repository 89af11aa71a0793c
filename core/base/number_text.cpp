#include "core/base/number_text.h"

#include <iomanip>
#include <sstream>

namespace rcb {

std::string fixed(double value, int digits) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(digits) << value;
    return s.str();
}

std::string bytes_text(double bytes) {
    const char* units[] = {"B", "KB", "MB", "GB", "TB"};
    int u = 0;
    while (bytes >= 1024 && u < 4) bytes /= 1024, ++u;
    return fixed(bytes, u == 0 ? 0 : 1) + " " + units[u];
}

}  // namespace rcb

#include "runner/table.h"

#include <algorithm>
#include <cstdio>
#include <iomanip>
#include <sstream>

namespace rcb {

void TextTable::print(std::ostream& out) const {
    std::vector<std::size_t> width;
    for (const auto& row : rows_) {
        if (width.size() < row.size()) width.resize(row.size(), 0);
        for (std::size_t c = 0; c < row.size(); ++c) width[c] = std::max(width[c], row[c].size());
    }
    for (const auto& row : rows_) {
        for (std::size_t c = 0; c < row.size(); ++c) {
            if (c) out << "  ";
            if (c == 0) out << std::left << std::setw(int(width[c])) << row[c];
            else out << std::right << std::setw(int(width[c])) << row[c];
        }
        out << '\n';
    }
}

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

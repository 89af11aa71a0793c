#include "cli/table.h"

#include <algorithm>
#include <iomanip>

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
            if (c == 0)
                out << std::left << std::setw(int(width[c])) << row[c];
            else
                out << std::right << std::setw(int(width[c])) << row[c];
        }
        out << '\n';
    }
}

}  // namespace rcb

#pragma once
/// Plain text tables for the terminal: columns right-aligned except the first.

#include <ostream>
#include <string>
#include <vector>

namespace rcb {

class TextTable {
public:
    explicit TextTable(std::vector<std::string> header) : rows_{std::move(header)} {}
    void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
    void print(std::ostream& out) const;

private:
    std::vector<std::vector<std::string>> rows_;
};

/// Fixed-point with `digits` decimals.
std::string fixed(double value, int digits);
/// "1.2 MB", "340 KB", "512 B".
std::string bytes_text(double bytes);

}  // namespace rcb

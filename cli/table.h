#pragma once
/// Plain text tables for the terminal: columns right-aligned except the first.

#include <ostream>
#include <string>
#include <vector>

#include "core/base/number_text.h"

namespace rcb {

class TextTable {
public:
    explicit TextTable(std::vector<std::string> header) : rows_{std::move(header)} {}
    void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
    void print(std::ostream& out) const;

private:
    std::vector<std::vector<std::string>> rows_;
};

}  // namespace rcb

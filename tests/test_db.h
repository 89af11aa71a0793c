#pragma once
/// The results database as the suites read it back: one integer a query returns (a count, a
/// column of one row, a PRAGMA), so that a test states its expectation on a plain number.

#include <cstdint>
#include <string>

#include "runner/sqlite.h"

namespace rcb::test {

/// The first column of the first row `sql` returns, as an integer; -1 when it returns no row (no
/// count is negative, so a missing row cannot pass for a value a test expects).
inline std::int64_t count(Database& db, const std::string& sql) {
    Statement s = db.prepare(sql);
    return s.step() ? s.int64(0) : -1;
}

}  // namespace rcb::test

#pragma once
/// Read-only SQL on a results database, for users who query it directly.

#include <string>
#include <vector>

#include "runner/sqlite.h"

namespace rcb {

struct QueryResult {
    std::vector<std::string> columns;
    std::vector<std::vector<std::string>> rows;  ///< NULL as ""
};

/// A statement to show users as an example of `rcbench query`.
inline constexpr const char* kQueryExample = "SELECT scene, structure, raycast_ns_median FROM cell_summary";

/// Runs one statement; InputError "query: ..." when it is not valid SQL or would write (only
/// SELECT, WITH and PRAGMA reads are allowed).
QueryResult read_only_query(Database& db, const std::string& sql);

}  // namespace rcb

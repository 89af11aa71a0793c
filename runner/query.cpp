#include "runner/query.h"

#include <memory>

#include "core/base/error.h"

namespace rcb {

QueryResult read_only_query(Database& db, const std::string& sql) {
    // One statement: SQLite would prepare the first and silently ignore the rest.
    const std::size_t end = sql.find(';');
    if (end != std::string::npos && sql.find_first_not_of(" \t\r\n;", end) != std::string::npos)
        throw InputError("query: give one SQL statement (found text after the first ';')");
    std::unique_ptr<Statement> s;
    try {
        s = std::make_unique<Statement>(db.prepare(sql));
    } catch (const std::runtime_error& e) {  // SqlError, or InputError for what the statement names
        throw InputError("query: " + std::string(e.what()));
    }
    if (!s->read_only()) throw InputError("query: only read-only statements are allowed (SELECT, WITH, PRAGMA reads)");
    QueryResult out;
    for (int i = 0; i < s->columns(); ++i) out.columns.push_back(s->column_name(i));
    try {
        while (s->step()) {
            std::vector<std::string> row;
            for (int i = 0; i < s->columns(); ++i) row.push_back(s->is_null(i) ? "" : s->text(i));
            out.rows.push_back(std::move(row));
        }
    } catch (const std::runtime_error& e) {
        throw InputError("query: " + std::string(e.what()));
    }
    return out;
}

}  // namespace rcb

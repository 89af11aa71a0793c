#include "runner/query.h"

#include <memory>

#include "core/error.h"

namespace rcb {

QueryResult read_only_query(Database& db, const std::string& sql) {
    std::unique_ptr<Statement> s;
    try {
        s = std::make_unique<Statement>(db.prepare(sql));
    } catch (const SqlError& e) {
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
    } catch (const SqlError& e) {
        throw InputError("query: " + std::string(e.what()));
    }
    return out;
}

}  // namespace rcb

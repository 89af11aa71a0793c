#include "runner/sqlite.h"

#include <chrono>
#include <thread>

namespace rcb {

Statement::Statement(sqlite3* db, const std::string& sql) : db_(db) {
    if (sqlite3_prepare_v2(db, sql.c_str(), int(sql.size()), &stmt_, nullptr) != SQLITE_OK)
        throw SqlError(std::string(sqlite3_errmsg(db)));
    if (!stmt_) throw SqlError("empty SQL statement");
}

Statement::~Statement() {
    if (stmt_) sqlite3_finalize(stmt_);
}

Statement& Statement::bind(int i, std::int64_t v) {
    if (sqlite3_bind_int64(stmt_, i, v) != SQLITE_OK) throw SqlError(sqlite3_errmsg(db_));
    return *this;
}
Statement& Statement::bind(int i, double v) {
    if (sqlite3_bind_double(stmt_, i, v) != SQLITE_OK) throw SqlError(sqlite3_errmsg(db_));
    return *this;
}
Statement& Statement::bind(int i, const std::string& v) {
    if (sqlite3_bind_text(stmt_, i, v.data(), int(v.size()), SQLITE_TRANSIENT) != SQLITE_OK) throw SqlError(sqlite3_errmsg(db_));
    return *this;
}
Statement& Statement::bind_null(int i) {
    if (sqlite3_bind_null(stmt_, i) != SQLITE_OK) throw SqlError(sqlite3_errmsg(db_));
    return *this;
}

bool Statement::step() {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    throw SqlError(sqlite3_errmsg(db_));
}

void Statement::run() {
    while (step()) {
    }
    reset();
}

void Statement::reset() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
}

std::string Statement::text(int i) const {
    const unsigned char* t = sqlite3_column_text(stmt_, i);
    return t ? std::string(reinterpret_cast<const char*>(t), std::size_t(sqlite3_column_bytes(stmt_, i))) : std::string();
}

Database::Database(const std::string& path, bool read_only) : path_(path) {
    const int flags = read_only ? SQLITE_OPEN_READONLY : (SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
    if (sqlite3_open_v2(path.c_str(), &db_, flags, nullptr) != SQLITE_OK) {
        std::string message = db_ ? sqlite3_errmsg(db_) : "out of memory";
        sqlite3_close(db_);
        db_ = nullptr;
        throw SqlError(message);
    }
    sqlite3_busy_timeout(db_, 60'000);
    sqlite3_extended_result_codes(db_, 1);
    if (!read_only) {
        // WAL is a property of the file: switch once. The switch needs an exclusive lock and SQLite
        // reports "locked" at once instead of waiting (e.g. while another process creates the same
        // new file), so retry for as long as the busy timeout would have waited.
        for (int attempt = 0;; ++attempt) {
            try {
                bool wal = false;
                {
                    Statement mode(db_, "PRAGMA journal_mode");  // finalised before the switch below
                    wal = mode.step() && mode.text(0) == "wal";
                }
                if (!wal) exec("PRAGMA journal_mode=WAL");
                break;
            } catch (const SqlError&) {
                if (attempt >= 6000) throw;
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
            }
        }
        exec("PRAGMA synchronous=NORMAL");
    }
    exec("PRAGMA foreign_keys=ON");
}

Database::~Database() {
    if (db_) sqlite3_close(db_);
}

void Database::exec(const std::string& sql) {
    char* error = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
        std::string message = error ? error : "unknown error";
        sqlite3_free(error);
        throw SqlError(message);
    }
}

}  // namespace rcb

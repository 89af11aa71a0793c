#include "runner/sqlite.h"

#include <chrono>
#include <thread>

#include "core/base/error.h"

namespace rcb {

void throw_sql_error(sqlite3* db, int rc) {
    const char* file = db ? sqlite3_db_filename(db, "main") : nullptr;
    const std::string where = file && *file ? std::string(file) + ": " : std::string();
    const std::string message = db ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
    const int primary = rc & 0xff;
    if (primary == SQLITE_CORRUPT || primary == SQLITE_NOTADB)
        throw InputError(where + "damaged or not an SQLite database (" + message + ")");
    if (primary == SQLITE_READONLY || primary == SQLITE_CANTOPEN || primary == SQLITE_PERM)
        throw InputError(where + "cannot write the database here (" + message + ")");
    throw SqlError(where + message, rc);
}

Statement::Statement(sqlite3* db, const std::string& sql) : db_(db) {
    if (const int rc = sqlite3_prepare_v2(db, sql.c_str(), int(sql.size()), &stmt_, nullptr); rc != SQLITE_OK)
        throw_sql_error(db, rc);
    if (!stmt_) throw SqlError("empty SQL statement");
}

Statement::~Statement() {
    if (stmt_) sqlite3_finalize(stmt_);
}

Statement& Statement::bind(int i, std::int64_t v) {
    if (const int rc = sqlite3_bind_int64(stmt_, i, v); rc != SQLITE_OK) throw_sql_error(db_, rc);
    return *this;
}
Statement& Statement::bind(int i, double v) {
    if (const int rc = sqlite3_bind_double(stmt_, i, v); rc != SQLITE_OK) throw_sql_error(db_, rc);
    return *this;
}
Statement& Statement::bind(int i, const std::string& v) {
    if (const int rc = sqlite3_bind_text(stmt_, i, v.data(), int(v.size()), SQLITE_TRANSIENT); rc != SQLITE_OK)
        throw_sql_error(db_, rc);
    return *this;
}
Statement& Statement::bind_null(int i) {
    if (const int rc = sqlite3_bind_null(stmt_, i); rc != SQLITE_OK) throw_sql_error(db_, rc);
    return *this;
}

bool Statement::step() {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    throw_sql_error(db_, rc);
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
    return t ? std::string(reinterpret_cast<const char*>(t), std::size_t(sqlite3_column_bytes(stmt_, i)))
             : std::string();
}

namespace {

int open_connection(const std::string& path, int flags, sqlite3** db) {
    const int rc = sqlite3_open_v2(path.c_str(), db, flags, nullptr);
    if (rc != SQLITE_OK) {
        sqlite3_close(*db);
        *db = nullptr;
    }
    return rc;
}

}  // namespace

Database::Database(const std::string& path, bool read_only) : path_(path) {
    // A reader opens the file for writing where it may (never creating it), so that closing the
    // last connection removes WAL's -wal and -shm files instead of leaving them beside a database
    // it only read; read-only where the file or folder is not writable.
    int rc =
        open_connection(path, read_only ? SQLITE_OPEN_READWRITE : (SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE), &db_);
    if (rc != SQLITE_OK && read_only) rc = open_connection(path, SQLITE_OPEN_READONLY, &db_);
    if (rc != SQLITE_OK) throw SqlError(path + ": " + sqlite3_errstr(rc), rc);
    try {
        configure(read_only);
    } catch (...) {
        sqlite3_close(db_);  // the destructor does not run for a constructor that throws
        db_ = nullptr;
        throw;
    }
}

std::unique_ptr<Database> Database::in_memory_copy(const Database& source) {
    auto copy = std::make_unique<Database>(":memory:", false);
    sqlite3_backup* backup = sqlite3_backup_init(copy->db_, "main", source.db_, "main");
    if (!backup) throw SqlError(source.path_ + ": " + sqlite3_errmsg(copy->db_), sqlite3_errcode(copy->db_));
    const int step = sqlite3_backup_step(backup, -1);
    const int rc = sqlite3_backup_finish(backup);
    if (step != SQLITE_DONE || rc != SQLITE_OK) throw SqlError(source.path_ + ": " + sqlite3_errstr(rc), rc);
    copy->path_ = source.path_;
    return copy;
}

void Database::configure(bool read_only) {
    sqlite3_busy_timeout(db_, 60'000);
    sqlite3_extended_result_codes(db_, 1);
    exec("PRAGMA foreign_keys=ON");
    if (read_only) return;
    bool wal = false, empty = false;
    {
        Statement mode(db_, "PRAGMA journal_mode");  // finalised before any switch
        wal = mode.step() && mode.text(0) == "wal";
        Statement pages(db_, "PRAGMA page_count");
        empty = pages.step() && pages.int64(0) == 0;
    }
    wal_pending_ = !wal;
    if (wal) exec("PRAGMA synchronous=NORMAL");
    // A new file has no header to keep: WAL at once, as before anything is written to it.
    if (empty) switch_to_wal();
}

void Database::switch_to_wal() {
    if (!wal_pending_) return;
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
        } catch (const SqlError& e) {
            // Only contention is worth waiting for; a file that is not a database fails at once.
            if ((e.code() != SQLITE_BUSY && e.code() != SQLITE_LOCKED) || attempt >= 6000) throw;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    }
    exec("PRAGMA synchronous=NORMAL");
    wal_pending_ = false;
}

Database::~Database() {
    if (db_) sqlite3_close(db_);
}

void Database::exec(const std::string& sql) {
    char* error = nullptr;
    if (const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error); rc != SQLITE_OK) {
        sqlite3_free(error);
        throw_sql_error(db_, rc);
    }
}

}  // namespace rcb

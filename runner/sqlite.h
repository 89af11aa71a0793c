#pragma once
/// A thin RAII layer over SQLite's C API: a connection, prepared statements with typed binds and
/// columns, and transactions that roll back unless committed. Errors throw with the SQL's message.

#include <sqlite3.h>

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <memory>
#include <string>

namespace rcb {

class SqlError : public std::runtime_error {
public:
    explicit SqlError(const std::string& what, int code = SQLITE_ERROR) : std::runtime_error(what), code_(code) {}
    /// SQLite's primary result code (SQLITE_BUSY, SQLITE_CORRUPT, ...).
    int code() const { return code_ & 0xff; }

private:
    int code_;
};

/// Throws for SQLite's result `rc` on `db`: an InputError naming the file when the file is damaged
/// or not a database (the user's input is wrong), else an SqlError naming the file.
[[noreturn]] void throw_sql_error(sqlite3* db, int rc);

class Statement {
public:
    Statement(sqlite3* db, const std::string& sql);
    ~Statement();
    Statement(Statement&& o) noexcept : db_(o.db_), stmt_(o.stmt_) { o.stmt_ = nullptr; }
    Statement(const Statement&) = delete;
    Statement& operator=(const Statement&) = delete;

    Statement& bind(int index, std::int64_t v);
    Statement& bind(int index, double v);
    Statement& bind(int index, const std::string& v);
    Statement& bind_null(int index);
    Statement& bind(int index, const std::optional<double>& v) { return v ? bind(index, *v) : bind_null(index); }
    /// Binds 1..n in order.
    template <typename... T>
    Statement& bind_all(const T&... values) {
        int i = 0;
        (bind(++i, values), ...);
        return *this;
    }

    /// Steps once: true while a row is available.
    bool step();
    /// Steps to completion (for statements without rows).
    void run();
    void reset();

    int columns() const { return sqlite3_column_count(stmt_); }
    std::string column_name(int i) const { return sqlite3_column_name(stmt_, i); }
    bool is_null(int i) const { return sqlite3_column_type(stmt_, i) == SQLITE_NULL; }
    std::int64_t int64(int i) const { return sqlite3_column_int64(stmt_, i); }
    double real(int i) const { return sqlite3_column_double(stmt_, i); }
    std::string text(int i) const;
    bool read_only() const { return sqlite3_stmt_readonly(stmt_) != 0; }

private:
    sqlite3* db_;
    sqlite3_stmt* stmt_ = nullptr;
};

class Database {
public:
    /// Opens (creating it unless read-only) with a busy timeout and, for writing, WAL journaling,
    /// so several processes can share one file. An existing file not yet in WAL mode is switched
    /// when the first transaction that wrote to it commits (switch_to_wal): a command refused
    /// before it wrote anything leaves the file's header as it was.
    Database(const std::string& path, bool read_only);
    ~Database();
    Database(const Database&) = delete;
    Database& operator=(const Database&) = delete;

    /// A writable copy of `source` in memory (SQLite's online backup); path() still names the file,
    /// for messages. Lets a reader migrate an older database without touching the file.
    static std::unique_ptr<Database> in_memory_copy(const Database& source);

    void exec(const std::string& sql);
    Statement prepare(const std::string& sql) { return Statement(db_, sql); }
    std::int64_t last_insert_id() const { return sqlite3_last_insert_rowid(db_); }
    const std::string& path() const { return path_; }
    /// Rows inserted, changed or deleted through this connection so far.
    std::int64_t total_changes() const { return sqlite3_total_changes64(db_); }
    /// Switches a writable file to WAL journaling once (outside any transaction); a no-op after.
    void switch_to_wal();

private:
    void configure(bool read_only);

    sqlite3* db_ = nullptr;
    std::string path_;
    bool wal_pending_ = false;  ///< writable, and not yet in WAL mode
};

/// BEGIN IMMEDIATE (takes the write lock up front, so concurrent writers queue instead of
/// deadlocking); rolls back on destruction unless commit() was called.
class Transaction {
public:
    explicit Transaction(Database& db) : db_(db), changes_(db.total_changes()) { db_.exec("BEGIN IMMEDIATE"); }
    ~Transaction() {
        if (!done_) try {
                db_.exec("ROLLBACK");
            } catch (...) {
            }
    }
    /// Commits; the first commit that changed rows also switches the file to WAL.
    void commit() {
        db_.exec("COMMIT");
        done_ = true;
        if (db_.total_changes() != changes_) db_.switch_to_wal();
    }

private:
    Database& db_;
    std::int64_t changes_;
    bool done_ = false;
};

}  // namespace rcb

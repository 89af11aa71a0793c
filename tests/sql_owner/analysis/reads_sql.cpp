// A file as tests/sql_owner.cmake must refuse outside runner/ (run on this folder by ctest).
void reads(Database& db) {
    // SELECT in a comment is prose, not a query.
    auto rows = db.prepare("SELECT id FROM run WHERE id = ?");
    Statement s = open(db);
    const char* text = "SQL, e.g. \"UPDATE this SET x = 1\"";
}

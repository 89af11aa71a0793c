#include "runner/archive.h"

#include <lzma.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <fstream>
#include <memory>
#include <regex>

#include "core/base/statistics.h"
#include "core/base/error.h"
#include "runner/build_info.h"
#include "runner/sqlite.h"
#include "runner/store.h"

namespace rcb {

namespace fs = std::filesystem;

namespace {

// ---- SHA-256, FIPS 180-4 section 6.2: 64 rounds over 512-bit blocks, big-endian words. ----

constexpr std::array<std::uint32_t, 64> kRound{
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
    0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
    0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
    0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
    0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
    0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
    0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
    0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2};

class Sha256 {
public:
    void update(const unsigned char* p, std::size_t n) {
        bytes_ += n;
        while (n > 0) {
            const std::size_t take = std::min(n, block_.size() - used_);
            std::copy(p, p + take, block_.begin() + std::ptrdiff_t(used_));
            used_ += take;
            p += take;
            n -= take;
            if (used_ == block_.size()) {
                compress();
                used_ = 0;
            }
        }
    }

    std::string hex() {
        const std::uint64_t bits = bytes_ * 8;
        const unsigned char one = 0x80, zero = 0;
        update(&one, 1);
        while (used_ != 56) update(&zero, 1);
        for (int i = 7; i >= 0; --i) {
            const auto b = static_cast<unsigned char>(bits >> (8 * i));
            update(&b, 1);
        }
        static constexpr char digits[] = "0123456789abcdef";
        std::string out;
        for (std::uint32_t word : h_)
            for (int i = 28; i >= 0; i -= 4) out += digits[(word >> i) & 15];
        return out;
    }

private:
    static std::uint32_t rotr(std::uint32_t x, int n) { return (x >> n) | (x << (32 - n)); }

    void compress() {
        std::array<std::uint32_t, 64> w{};
        for (int i = 0; i < 16; ++i)
            w[i] = std::uint32_t(block_[4 * i]) << 24 | std::uint32_t(block_[4 * i + 1]) << 16 |
                   std::uint32_t(block_[4 * i + 2]) << 8 | std::uint32_t(block_[4 * i + 3]);
        for (int i = 16; i < 64; ++i) {
            const std::uint32_t s0 = rotr(w[i - 15], 7) ^ rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
            const std::uint32_t s1 = rotr(w[i - 2], 17) ^ rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
            w[i] = w[i - 16] + s0 + w[i - 7] + s1;
        }
        std::array<std::uint32_t, 8> v = h_;
        for (int i = 0; i < 64; ++i) {
            const std::uint32_t s1 = rotr(v[4], 6) ^ rotr(v[4], 11) ^ rotr(v[4], 25);
            const std::uint32_t ch = (v[4] & v[5]) ^ (~v[4] & v[6]);
            const std::uint32_t t1 = v[7] + s1 + ch + kRound[i] + w[i];
            const std::uint32_t s0 = rotr(v[0], 2) ^ rotr(v[0], 13) ^ rotr(v[0], 22);
            const std::uint32_t maj = (v[0] & v[1]) ^ (v[0] & v[2]) ^ (v[1] & v[2]);
            std::rotate(v.rbegin(), v.rbegin() + 1, v.rend());  // h = g, g = f, ..., b = a
            v[4] += t1;
            v[0] = t1 + s0 + maj;
        }
        for (int i = 0; i < 8; ++i) h_[i] += v[i];
    }

    std::array<std::uint32_t, 8> h_{0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
                                    0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19};
    std::array<unsigned char, 64> block_{};
    std::size_t used_ = 0;
    std::uint64_t bytes_ = 0;
};

// ---- xz streams (liblzma's stream API: lzma_easy_encoder, lzma_stream_decoder). ----

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

File open_file(const fs::path& path, const char* mode) {
    File f(std::fopen(path.c_str(), mode));
    if (!f) throw InputError(path.string() + ": cannot open for " + (mode[0] == 'r' ? "reading" : "writing"));
    return f;
}

/// Runs an initialised lzma stream from the file `in` into `dst` (the file `out`).
void code_lzma(lzma_stream& strm, const fs::path& in, std::FILE* dst, const fs::path& out) {
    File src = open_file(in, "rb");
    std::vector<std::uint8_t> inbuf(1 << 16), outbuf(1 << 16);
    lzma_action action = LZMA_RUN;
    strm.next_out = outbuf.data();
    strm.avail_out = outbuf.size();
    for (;;) {
        if (strm.avail_in == 0 && action == LZMA_RUN) {
            strm.next_in = inbuf.data();
            strm.avail_in = std::fread(inbuf.data(), 1, inbuf.size(), src.get());
            if (std::ferror(src.get())) throw std::runtime_error(in.string() + ": read error");
            if (std::feof(src.get())) action = LZMA_FINISH;
        }
        const lzma_ret ret = lzma_code(&strm, action);
        if (strm.avail_out == 0 || ret == LZMA_STREAM_END) {
            const std::size_t n = outbuf.size() - strm.avail_out;
            if (std::fwrite(outbuf.data(), 1, n, dst) != n) throw std::runtime_error(out.string() + ": write error");
            strm.next_out = outbuf.data();
            strm.avail_out = outbuf.size();
        }
        if (ret == LZMA_STREAM_END) break;
        if (ret != LZMA_OK)
            throw InputError(in.string() + ": not a complete xz stream (liblzma error " + std::to_string(int(ret)) +
                             ")");
    }
    if (std::fflush(dst) != 0) throw std::runtime_error(out.string() + ": write error");
}

/// code_lzma into a new file `out` (never replacing one), removed again when it fails.
void run_lzma(lzma_stream& strm, const fs::path& in, const fs::path& out) {
    std::unique_ptr<lzma_stream, void (*)(lzma_stream*)> guard(&strm, lzma_end);
    File dst = open_file(out, "wbx");  // "x": fails on an existing file
    try {
        code_lzma(strm, in, dst.get(), out);
    } catch (...) {
        dst.reset();
        std::error_code ec;
        fs::remove(out, ec);
        throw;
    }
}

/// Removes a temporary file when it goes out of scope, unless released.
class TempFile {
public:
    explicit TempFile(fs::path p) : path_(std::move(p)) {}
    ~TempFile() {
        std::error_code ec;
        if (!path_.empty()) fs::remove(path_, ec);
    }
    TempFile(const TempFile&) = delete;
    TempFile& operator=(const TempFile&) = delete;
    const fs::path& path() const { return path_; }

private:
    fs::path path_;
};

/// `out` must not exist: a finished file is published only once, by a hard link (which fails
/// rather than replace), so a second writer of the same name cannot overwrite the first.
void publish(const fs::path& tmp, const fs::path& out) {
    std::error_code ec;
    fs::create_hard_link(tmp, out, ec);
    if (ec) throw InputError(out.string() + ": cannot write (" + ec.message() + "); archived data is never replaced");
}

fs::path temp_beside(const fs::path& out) {
    return out.parent_path() / (out.filename().string() + "." + std::to_string(::getpid()) + ".tmp");
}

// ---- What an export records. ----

bool dirty_commit(const std::string& commit) {
    return commit.empty() || commit == "unknown" ||
           (commit.size() >= 6 && commit.compare(commit.size() - 6, 6, "-dirty") == 0);
}

/// One run's provenance: the binary's commit and build, the machine, when, and the load it ran under.
nlohmann::json describe_run(Database& db, Statement& r) {
    const std::int64_t id = r.int64(0);
    nlohmann::json run{{"id", id},
                       {"uuid", r.text(1)},
                       {"experiment", r.text(2)},
                       {"started_at", r.text(3)},
                       {"finished_at", r.is_null(4) ? nlohmann::json() : nlohmann::json(r.text(4))},
                       {"git_commit", r.text(5)},
                       {"dirty", dirty_commit(r.text(5))},
                       {"compiler", r.text(6)},
                       {"cpu_model", r.text(7)},
                       {"cores", r.int64(8)},
                       {"governor", r.text(9)},
                       {"hostname", r.text(10)},
                       {"threads", r.int64(11)},
                       {"shard", r.text(12)}};
    Statement cells = db.prepare("SELECT count(*) FROM cell WHERE run_id = ?");
    cells.bind_all(id);
    cells.step();
    run["cells"] = cells.int64(0);
    Statement state = db.prepare(
        "SELECT cell_state.load_1m, cell_state.slow FROM cell_state JOIN cell ON cell.id = cell_state.cell_id "
        "WHERE cell.run_id = ?");
    state.bind_all(id);
    std::vector<double> load;
    std::int64_t slow = 0;
    while (state.step()) {
        if (state.real(0) >= 0) load.push_back(state.real(0));
        slow += state.int64(1);
    }
    run["load_1m"] = {{"median", load.empty() ? -1.0 : median(load)},
                      {"max", load.empty() ? -1.0 : *std::max_element(load.begin(), load.end())}};
    run["slow_cells"] = slow;
    return run;
}

nlohmann::json describe_runs(Database& db) {
    nlohmann::json runs = nlohmann::json::array();
    Statement r = db.prepare(
        "SELECT run.id, run.uuid, experiment.name, run.started_at, run.finished_at, run.git_commit, run.compiler, "
        "run.cpu_model, run.cores, run.governor, run.hostname, run.threads, run.shard FROM run JOIN experiment ON "
        "experiment.id = run.experiment_id ORDER BY run.id");
    while (r.step()) runs.push_back(describe_run(db, r));
    return runs;
}

nlohmann::json row_counts(Database& db) {
    std::vector<std::string> tables;
    Statement t =
        db.prepare("SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' ORDER BY name");
    while (t.step()) tables.push_back(t.text(0));
    nlohmann::json counts = nlohmann::json::object();
    for (const std::string& name : tables) {
        Statement c = db.prepare("SELECT count(*) FROM \"" + name + "\"");
        c.step();
        counts[name] = c.int64(0);
    }
    return counts;
}

void check_integrity(Database& db, const std::string& what) {
    Statement s = db.prepare("PRAGMA integrity_check(1)");
    if (!s.step() || s.text(0) != "ok")
        throw InputError(what + ": damaged results database (integrity check: " + (s.columns() ? s.text(0) : "") + ")");
}

void check_name(const std::string& name) {
    static const std::regex ok("[A-Za-z0-9][A-Za-z0-9._-]*");
    if (!std::regex_match(name, ok) || name.size() > 100)
        throw InputError("--name " + quoted_excerpt(name) +
                         ": expected letters, digits, '.', '_' or '-', starting with a letter or digit");
}

/// The source's runs copied into a new database file `out`, minus what no command reads back.
void export_database(Database& source, const fs::path& out) {
    Statement into = source.prepare("VACUUM INTO ?");
    into.bind(1, out.string());
    into.run();
    Database copy(out.string(), false);
    // frame.stats: Structure::stats() after each frame, which no reading command uses; a database's
    // largest column. NOT NULL in the schema, so an empty object stands for it.
    copy.exec("UPDATE frame SET stats = '{}'");
    copy.exec("PRAGMA journal_mode = DELETE");  // one self-contained file, no -wal beside it
    copy.exec("VACUUM");
    check_integrity(copy, out.string());
}

fs::path manifest_path(const fs::path& export_xz) {
    const std::string file = export_xz.filename().string();
    const std::string suffix = ".db.xz";
    if (file.size() <= suffix.size() || file.compare(file.size() - suffix.size(), suffix.size(), suffix) != 0)
        throw InputError(export_xz.string() + ": not an archived export (expected NAME.db.xz)");
    return export_xz.parent_path() / (file.substr(0, file.size() - suffix.size()) + ".json");
}

}  // namespace

std::string sha256_hex(std::string_view bytes) {
    Sha256 h;
    h.update(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size());
    return h.hex();
}

std::string sha256_file(const fs::path& path) {
    File f = open_file(path, "rb");
    Sha256 h;
    std::vector<unsigned char> buf(1 << 16);
    std::size_t n = 0;
    while ((n = std::fread(buf.data(), 1, buf.size(), f.get())) > 0) h.update(buf.data(), n);
    if (std::ferror(f.get())) throw InputError(path.string() + ": read error");
    return h.hex();
}

void xz_compress_file(const fs::path& in, const fs::path& out) {
    lzma_stream strm = LZMA_STREAM_INIT;
    if (lzma_easy_encoder(&strm, 6, LZMA_CHECK_CRC64) != LZMA_OK)
        throw std::runtime_error("liblzma: cannot start the xz encoder");
    run_lzma(strm, in, out);
}

void xz_decompress_file(const fs::path& in, const fs::path& out) {
    lzma_stream strm = LZMA_STREAM_INIT;
    if (lzma_stream_decoder(&strm, UINT64_MAX, 0) != LZMA_OK)
        throw std::runtime_error("liblzma: cannot start the xz decoder");
    run_lzma(strm, in, out);
}

nlohmann::json add_to_archive(const ArchiveRequest& request) {
    check_name(request.name);
    if (request.command.empty()) throw InputError("--command: give the command that made the runs");
    const fs::path xz = request.archive_dir / (request.name + ".db.xz");
    const fs::path json = request.archive_dir / (request.name + ".json");
    for (const fs::path& p : {xz, json})
        if (fs::exists(p))
            throw InputError(p.string() +
                             ": the archive holds an export of this name; archived data is added to, never edited "
                             "(choose another --name)");
    auto source = open_read_only(request.source);
    check_integrity(*source, request.source);
    nlohmann::json runs = describe_runs(*source);
    if (runs.empty()) throw InputError(request.source + ": no runs to archive");
    bool dirty = false;
    for (const auto& run : runs) {
        if (!run["dirty"].get<bool>()) continue;
        dirty = true;
        if (!request.allow_dirty)
            throw InputError(request.source + ": run " + std::to_string(run["id"].get<std::int64_t>()) +
                             " was made by a binary built from a dirty or unknown tree (git_commit " +
                             quoted_excerpt(run["git_commit"].get<std::string>()) +
                             "); archive runs of committed code, or pass --allow-dirty to archive it marked dirty");
    }
    std::error_code dir_error;
    fs::create_directories(request.archive_dir, dir_error);
    if (dir_error || !fs::is_directory(request.archive_dir))
        throw InputError("--archive " + request.archive_dir.string() + ": not a folder rcbench can write");
    TempFile db_tmp(temp_beside(request.archive_dir / (request.name + ".db")));
    export_database(*source, db_tmp.path());
    source.reset();
    nlohmann::json manifest{{"name", request.name},
                            {"file", xz.filename().string()},
                            {"source", fs::path(request.source).filename().string()},
                            {"command", request.command},
                            {"archived_at", utc_now()},
                            {"archived_with", kGitCommit},
                            {"dirty", dirty},
                            {"schema_version", latest_schema_version()},
                            {"dropped", {"frame.stats (set to {})"}},
                            {"runs", runs}};
    {
        Database copy(db_tmp.path().string(), true);
        manifest["rows"] = row_counts(copy);
    }
    manifest["db_sha256"] = sha256_file(db_tmp.path());
    manifest["db_bytes"] = std::int64_t(fs::file_size(db_tmp.path()));
    TempFile xz_tmp(temp_beside(xz));
    xz_compress_file(db_tmp.path(), xz_tmp.path());
    manifest["sha256"] = sha256_file(xz_tmp.path());
    manifest["bytes"] = std::int64_t(fs::file_size(xz_tmp.path()));
    TempFile json_tmp(temp_beside(json));
    {
        File f = open_file(json_tmp.path(), "wbx");
        const std::string text = manifest.dump(2) + "\n";
        if (std::fwrite(text.data(), 1, text.size(), f.get()) != text.size() || std::fflush(f.get()) != 0)
            throw std::runtime_error(json_tmp.path().string() + ": write error");
    }
    publish(xz_tmp.path(), xz);
    try {
        publish(json_tmp.path(), json);
    } catch (...) {
        std::error_code ec;
        fs::remove(xz, ec);  // ours, written a moment ago: an export without its manifest is no export
        throw;
    }
    return manifest;
}

nlohmann::json read_manifest(const fs::path& export_xz) {
    const fs::path path = manifest_path(export_xz);
    std::ifstream in(path);
    if (!in) throw InputError(path.string() + ": no manifest for " + export_xz.filename().string());
    try {
        nlohmann::json m = nlohmann::json::parse(in);
        const auto need = [&](bool ok, const std::string& what) {
            if (!ok) throw InputError(path.string() + ": manifest without " + what);
        };
        need(m.is_object(), "an object");
        for (const char* key : {"name", "sha256", "db_sha256", "archived_at", "command"})
            need(m.contains(key) && m[key].is_string(), std::string("a string \"") + key + "\"");
        need(m.contains("bytes") && m["bytes"].is_number_integer(), "an integer \"bytes\"");
        need(m.contains("dirty") && m["dirty"].is_boolean(), "a boolean \"dirty\"");
        need(m.contains("runs") && m["runs"].is_array(), "an array \"runs\"");
        for (const auto& r : m["runs"])
            need(r.is_object() && r.contains("experiment") && r["experiment"].is_string() && r.contains("git_commit") &&
                     r["git_commit"].is_string(),
                 "each run's \"experiment\" and \"git_commit\"");
        return m;
    } catch (const nlohmann::json::exception& e) {
        throw InputError(path.string() + ": not a readable manifest (" + e.what() + ")");
    }
}

void unpack_export(const fs::path& export_xz, const fs::path& out) {
    const nlohmann::json m = read_manifest(export_xz);
    if (sha256_file(export_xz) != m["sha256"].get<std::string>())
        throw InputError(export_xz.string() +
                         ": SHA-256 differs from its manifest's: the export was edited or damaged");
    if (fs::exists(out)) throw InputError(out.string() + ": exists; unpack writes a new file");
    TempFile tmp(temp_beside(out));
    xz_decompress_file(export_xz, tmp.path());
    if (sha256_file(tmp.path()) != m["db_sha256"].get<std::string>())
        throw InputError(export_xz.string() + ": the unpacked database's SHA-256 differs from its manifest's");
    publish(tmp.path(), out);
}

std::vector<nlohmann::json> verify_archive(const fs::path& archive_dir) {
    if (!fs::is_directory(archive_dir)) throw InputError(archive_dir.string() + ": no such archive folder");
    std::vector<fs::path> exports, manifests;
    for (const auto& entry : fs::directory_iterator(archive_dir)) {
        const std::string file = entry.path().filename().string();
        if (file.size() > 6 && file.compare(file.size() - 6, 6, ".db.xz") == 0) exports.push_back(entry.path());
        if (file.size() > 5 && file.compare(file.size() - 5, 5, ".json") == 0) manifests.push_back(entry.path());
    }
    std::sort(exports.begin(), exports.end());
    for (const fs::path& json : manifests) {
        const std::string stem = json.stem().string();
        if (!fs::exists(archive_dir / (stem + ".db.xz")))
            throw InputError(json.string() + ": a manifest without its export " + stem + ".db.xz");
    }
    std::vector<nlohmann::json> out;
    for (const fs::path& xz : exports) {
        nlohmann::json m = read_manifest(xz);
        const std::string stem = manifest_path(xz).stem().string();
        if (m["name"] != stem)
            throw InputError(manifest_path(xz).string() + ": manifest names " +
                             quoted_excerpt(m["name"].get<std::string>()));
        if (sha256_file(xz) != m["sha256"].get<std::string>())
            throw InputError(xz.string() + ": SHA-256 differs from its manifest's: the export was edited or damaged");
        out.push_back(std::move(m));
    }
    return out;
}

}  // namespace rcb

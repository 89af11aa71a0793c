// The results archive (runner/archive.h, scripts/reproduce.sh): SHA-256 and xz as their standards
// say, an export that unpacks to the runs it was made from with its provenance in the manifest, an
// archive that refuses to be edited (no second export of a name, no dirty tree unmarked, no byte
// changed), and a doc figure that differs from its regenerated output failing the check.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "accel/registry.h"
#include "core/base/random.h"
#include "runner/archive.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tests/test_db.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

std::string read_bytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

void write_bytes(const fs::path& p, const std::string& bytes) {
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << bytes;
}

/// A finished run of two cells of five frames (frames with stats, as the runner stores them), its
/// binary's commit `commit`.
void make_results(const fs::path& path, const std::string& commit) {
    ResultStore store(path.string());
    Experiment e;
    e.name = "archived";
    e.content = "{}";
    e.hash = "hash-archived";
    const std::int64_t experiment = store.experiment_id(e);
    RunInfo info = RunInfo::current(1, "", e);
    info.git_commit = commit;
    const std::int64_t run = store.begin_run(experiment, info);
    for (const std::string structure : {"bf", "ug"}) {
        SceneSpec spec;
        spec.name = "scene";
        spec.key = {{"kind", "uniform"}, {"objects", 1}};
        Recording r;
        r.initial.push_back(Object{1, {{0, 0, 0}, {1, 1, 1}}});
        SimulationResult res;
        res.structure = structure;
        res.params = find_structure(structure).defaults();
        res.objects = 1;
        for (std::uint32_t i = 1; i <= 5; ++i) {
            FrameResult f;
            f.frame = i;
            f.rays = 100;
            f.update_ns = 1000 * i;
            f.raycast_ns = 5000 + 10 * i;
            f.counters.n_rb = 100;
            f.stats = {{"nodes", 7 * i}, {"what", "a structure's own statistics"}};
            res.frames.push_back(f);
        }
        Cell c;
        c.key = structure;
        ASSERT_TRUE(store.store_cell(run, experiment, c, spec, r, "scene-hash", res));
    }
    store.finish_run(run);
}

ArchiveRequest request(const test::TempDir& dir, const std::string& db, const std::string& name) {
    ArchiveRequest a;
    a.source = dir.file(db);
    a.name = name;
    a.command = "rcbench run experiments/archived.json --db " + db;
    a.archive_dir = dir.path() / "archive";
    return a;
}

TEST(Archive, Sha256MatchesTheStandardsTestVectors) {
    // FIPS 180-4's examples (NIST's SHA256.pdf) and the empty message.
    EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    EXPECT_EQ(sha256_hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
              "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
    EXPECT_EQ(sha256_hex(std::string(1000000, 'a')),
              "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
    test::TempDir dir("archive");
    write_bytes(dir.path() / "abc", "abc");
    EXPECT_EQ(sha256_file(dir.path() / "abc"), sha256_hex("abc"));
}

TEST(Archive, XzKeepsEveryByteAndRefusesWhatIsNotXz) {
    test::TempDir dir("archive");
    Random rng(7);
    std::string bytes;
    for (int i = 0; i < 300000; ++i) bytes += char(rng.below(4) == 0 ? rng.below(256) : std::uint64_t('x'));
    write_bytes(dir.path() / "in", bytes);
    xz_compress_file(dir.path() / "in", dir.path() / "in.xz");
    EXPECT_LT(fs::file_size(dir.path() / "in.xz"), bytes.size() / 2);
    xz_decompress_file(dir.path() / "in.xz", dir.path() / "out");
    EXPECT_EQ(read_bytes(dir.path() / "out"), bytes);
    write_bytes(dir.path() / "plain.xz", "not xz at all");
    test::expect_input_error([&] { xz_decompress_file(dir.path() / "plain.xz", dir.path() / "out2"); }, "plain.xz");
}

TEST(Archive, AnExportUnpacksToTheRunsItWasMadeFromWithTheirProvenance) {
    test::TempDir dir("archive");
    make_results(dir.path() / "run.db", "0123456789ab");
    const nlohmann::json m = add_to_archive(request(dir, "run.db", "pilot"));
    const fs::path xz = dir.path() / "archive" / "pilot.db.xz";
    ASSERT_TRUE(fs::exists(xz));
    EXPECT_EQ(read_manifest(xz), m);
    EXPECT_EQ(m["sha256"], sha256_file(xz));
    EXPECT_EQ(m["bytes"], std::int64_t(fs::file_size(xz)));
    EXPECT_EQ(m["command"], "rcbench run experiments/archived.json --db run.db");
    EXPECT_EQ(m["source"], "run.db");
    EXPECT_EQ(m["dirty"], false);
    ASSERT_EQ(m["runs"].size(), 1u);
    EXPECT_EQ(m["runs"][0]["git_commit"], "0123456789ab");
    EXPECT_EQ(m["runs"][0]["experiment"], "archived");
    EXPECT_EQ(m["runs"][0]["cells"], 2);
    for (const char* key : {"cpu_model", "hostname", "started_at", "finished_at", "load_1m"})
        EXPECT_TRUE(m["runs"][0].contains(key)) << key;
    EXPECT_EQ(m["rows"]["frame"], 10);
    EXPECT_EQ(m["schema_version"], latest_schema_version());

    unpack_export(xz, dir.path() / "unpacked.db");
    auto db = open_read_only(dir.file("unpacked.db"));
    EXPECT_EQ(test::count(*db, "SELECT count(*) FROM frame"), 10);
    EXPECT_EQ(test::count(*db, "SELECT count(*) FROM frame WHERE stats <> '{}'"), 0);  // dropped
    EXPECT_EQ(test::count(*db, "SELECT sum(raycast_ns) FROM frame"), 2 * (5 * 5000 + 10 * 15));
    EXPECT_EQ(test::count(*db, "SELECT count(*) FROM run WHERE finished_at IS NOT NULL"), 1);
    EXPECT_EQ(test::count(*db, "PRAGMA user_version"), latest_schema_version());
    // The unpacked file is byte for byte the database the manifest describes.
    EXPECT_EQ(sha256_file(dir.path() / "unpacked.db"), m["db_sha256"]);
    test::expect_input_error([&] { unpack_export(xz, dir.path() / "unpacked.db"); }, "exists");
}

TEST(Archive, RefusesToOverwriteAnArchivedExport) {
    test::TempDir dir("archive");
    make_results(dir.path() / "a.db", "0123456789ab");
    make_results(dir.path() / "b.db", "ba9876543210");
    add_to_archive(request(dir, "a.db", "pilot"));
    const fs::path xz = dir.path() / "archive" / "pilot.db.xz", json = dir.path() / "archive" / "pilot.json";
    const std::string before_xz = read_bytes(xz), before_json = read_bytes(json);
    test::expect_input_error([&] { add_to_archive(request(dir, "b.db", "pilot")); }, "never edited");
    EXPECT_EQ(read_bytes(xz), before_xz);
    EXPECT_EQ(read_bytes(json), before_json);
    // A manifest alone (an interrupted copy, a hand-made file) holds the name as well.
    write_bytes(dir.path() / "archive" / "other.json", "{}");
    test::expect_input_error([&] { add_to_archive(request(dir, "b.db", "other")); }, "never edited");
    EXPECT_FALSE(fs::exists(dir.path() / "archive" / "other.db.xz"));
    test::expect_input_error([&] { add_to_archive(request(dir, "b.db", "../escape")); }, "--name");
}

TEST(Archive, RefusesADirtyTreeUnlessAllowedAndThenMarksIt) {
    test::TempDir dir("archive");
    make_results(dir.path() / "dirty.db", "0123456789ab-dirty");
    test::expect_input_error([&] { add_to_archive(request(dir, "dirty.db", "d")); }, "dirty");
    EXPECT_FALSE(fs::exists(dir.path() / "archive" / "d.db.xz"));
    EXPECT_FALSE(fs::exists(dir.path() / "archive" / "d.json"));
    ArchiveRequest allowed = request(dir, "dirty.db", "d");
    allowed.allow_dirty = true;
    const nlohmann::json m = add_to_archive(allowed);
    EXPECT_EQ(m["dirty"], true);
    EXPECT_EQ(m["runs"][0]["dirty"], true);
}

TEST(Archive, VerifyNamesAnExportEditedAfterItWasArchived) {
    test::TempDir dir("archive");
    make_results(dir.path() / "run.db", "0123456789ab");
    add_to_archive(request(dir, "run.db", "one"));
    add_to_archive(request(dir, "run.db", "two"));
    EXPECT_EQ(verify_archive(dir.path() / "archive").size(), 2u);
    const fs::path xz = dir.path() / "archive" / "two.db.xz";
    std::string bytes = read_bytes(xz);
    bytes[bytes.size() / 2] ^= 1;
    write_bytes(xz, bytes);
    test::expect_input_error([&] { verify_archive(dir.path() / "archive"); }, "two.db.xz: SHA-256 differs");
    test::expect_input_error([&] { unpack_export(xz, dir.path() / "x.db"); }, "edited or damaged");
    EXPECT_FALSE(fs::exists(dir.path() / "x.db"));
    fs::remove(xz);
    test::expect_input_error([&] { verify_archive(dir.path() / "archive"); },
                             "two.json: a manifest without its export");
}

/// A checkout in miniature for scripts/reproduce.sh: one export, one registered figure in one doc.
struct MiniCheckout {
    explicit MiniCheckout(const test::TempDir& dir) : root(dir.path() / "root") {
        make_results(dir.path() / "run.db", "0123456789ab");
        ArchiveRequest a = request(dir, "run.db", "mini");
        a.archive_dir = root / "results" / "archive";
        add_to_archive(a);
        write_bytes(root / "docs" / "figures.json", R"({"figures": [{"name": "frames", "doc": "docs/page.md",
            "format": "text", "exports": ["mini"],
            "commands": [["query", "{mini}", "SELECT config.structure, count(*) AS frames FROM frame JOIN cell ON cell.id = frame.cell_id JOIN config ON config.id = cell.config_id GROUP BY config.structure ORDER BY config.structure"]]}]})");
        write_bytes(root / "docs" / "page.md",
                    "# A page\n\n<!-- figure: frames -->\nstale\n<!-- /figure -->\n\nAfter.\n");
    }
    ::test::Outcome reproduce(const std::vector<std::string>& args) const {
        std::vector<std::string> argv{std::string(RCBENCH_SOURCE_DIR) + "/scripts/reproduce.sh", "--root",
                                      root.string(), "--rcbench", RCBENCH_BINARY};
        argv.insert(argv.end(), args.begin(), args.end());
        ::test::RunOptions o;
        o.timeout_seconds = 120;
        return ::test::run_process(argv, o);
    }
    fs::path root;
};

TEST(Archive, ADocFigureThatDiffersFromItsRegeneratedOutputFailsTheCheck) {
    test::TempDir dir("archive");
    const MiniCheckout c(dir);
    const fs::path page = c.root / "docs" / "page.md";
    ::test::Outcome r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("figure frames in docs/page.md differs from its regenerated output"), std::string::npos)
        << r.err;
    EXPECT_NE(read_bytes(page).find("stale"), std::string::npos);  // --check writes nothing

    r = c.reproduce({});
    ASSERT_EQ(r.code, 0) << r.err;
    const std::string written = read_bytes(page);
    EXPECT_NE(written.find("<!-- figure: frames -->\n```text\n"), std::string::npos) << written;
    EXPECT_NE(written.find("bf"), std::string::npos) << written;
    EXPECT_EQ(written.find("stale"), std::string::npos) << written;
    EXPECT_NE(written.find("<!-- /figure -->\n\nAfter.\n"), std::string::npos) << written;
    r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 0) << r.err;

    // One number of the table changed by hand: the check fails and names the figure.
    std::string edited = written;
    edited.replace(edited.find("5\n"), 1, "6");
    write_bytes(page, edited);
    r = c.reproduce({"--check", "frames"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("figure frames in docs/page.md differs"), std::string::npos) << r.err;
}

TEST(Archive, AShardRegeneratesItsShareOfTheFiguresAndChecksEveryDoc) {
    // The mini checkout's one figure is figure 0: shard 1/2 holds it, shard 2/2 does not.
    test::TempDir dir("archive");
    const MiniCheckout c(dir);
    ::test::Outcome r = c.reproduce({"--check", "--shard", "1/2"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("figure frames in docs/page.md differs"), std::string::npos) << r.err;
    r = c.reproduce({"--check", "--shard", "2/2"});
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out.find("figure frames"), std::string::npos) << r.out;
    // The checks of every doc still run in a shard without the figure.
    write_bytes(c.root / "README.md", "<!-- figure: unregistered -->\nnumbers\n<!-- /figure -->\n");
    r = c.reproduce({"--check", "--shard", "2/2"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("marks figure unregistered"), std::string::npos) << r.err;
    for (const char* bad : {"0/2", "3/2", "1", "a/b"}) {
        r = c.reproduce({"--check", "--shard", bad});
        EXPECT_EQ(r.code, 2) << bad;
        EXPECT_NE(r.err.find("--shard needs K/N"), std::string::npos) << r.err;
    }
}

TEST(Archive, ReproduceRefusesAFigureWithoutArchivedDataAndAnEditedExport) {
    test::TempDir dir("archive");
    const MiniCheckout c(dir);
    ASSERT_EQ(c.reproduce({}).code, 0);
    write_bytes(c.root / "README.md", "<!-- figure: unregistered -->\nnumbers\n<!-- /figure -->\n");
    ::test::Outcome r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("README.md marks figure unregistered, which docs/figures.json does not register"),
              std::string::npos)
        << r.err;
    fs::remove(c.root / "README.md");
    ASSERT_EQ(c.reproduce({"--check"}).code, 0);

    const fs::path xz = c.root / "results" / "archive" / "mini.db.xz";
    std::string bytes = read_bytes(xz);
    bytes[bytes.size() / 3] ^= 4;
    write_bytes(xz, bytes);
    r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("mini.db.xz: SHA-256 differs"), std::string::npos) << r.err;
}

TEST(Archive, ATableOfMeasuredNumbersOutsideAFigureFailsTheCheckNamingItsLine) {
    test::TempDir dir("archive");
    const MiniCheckout c(dir);
    ASSERT_EQ(c.reproduce({}).code, 0);
    const fs::path page = c.root / "docs" / "page.md";
    const std::string figure = read_bytes(page);
    // Tables of constants and formats pass: no unit, a code block, or the marker before a table
    // whose numbers are settings.
    const std::string constants =
        "\n| parameter | default |\n|---|---|\n| `density` | 4.0 |\n\n"
        "```text\n| rays | 1.5 ms |\n```\n\n"
        "<!-- not-a-figure -->\n| key | meaning |\n|---|---|\n| `change_fraction` | 1% of the objects per frame |\n";
    write_bytes(page, figure + constants);
    ::test::Outcome r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 0) << r.err;

    // A time with its unit, outside any figure: the check names the line of that row.
    write_bytes(page, figure + constants + "\n| structure | rays |\n|---|---|\n| wbvh | 0.41 ms |\n");
    const std::size_t wbvh_line = 1 + std::size_t(std::count(figure.begin(), figure.end(), '\n')) +
                                  std::size_t(std::count(constants.begin(), constants.end(), '\n')) + 3;
    r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(
        r.err.find("docs/page.md:" + std::to_string(wbvh_line) + ": a table of measured numbers outside a figure"),
        std::string::npos)
        << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;

    // Ratios under a header that names them, without a unit in the cells, fail too.
    write_bytes(page, figure + "\n| scene | all ÷ closest |\n|---|---|\n| oa_dm4 | 1.15 |\n");
    r = c.reproduce({"--check"});
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("docs/page.md:"), std::string::npos) << r.err;
}

TEST(Archive, TheCommandRefusesAnArchivedNameWithExitTwo) {
    test::TempDir dir("archive");
    make_results(dir.path() / "run.db", "0123456789ab");
    const std::vector<std::string> add{RCBENCH_BINARY, "archive",
                                       "add",          dir.file("run.db"),
                                       "--name",       "pilot",
                                       "--command",    "rcbench run x.json",
                                       "--archive",    dir.file("archive")};
    ::test::Outcome r = ::test::run_process(add);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("archived pilot: 1 runs of archived (commit 0123456789ab), 2 cells, 10 frames"),
              std::string::npos)
        << r.out;
    r = ::test::run_process(add);
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("never edited"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    r = ::test::run_process({RCBENCH_BINARY, "archive", "verify", dir.file("archive")});
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("1 exports in"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace rcb

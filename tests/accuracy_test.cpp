// Speed against accuracy: the per-frame accuracy columns of the results database (schema
// version 7) and their migration, read back and merged.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include "core/registry.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/store.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("rcb_accuracy_" + std::to_string(::getpid()) + "_" + name);
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

std::int64_t count(Database& db, const std::string& sql) {
    Statement s = db.prepare(sql);
    s.step();
    return s.int64(0);
}

TEST(AccuracyColumns, FramesOfAnOlderDatabaseReadAsTheirMismatchCountsSay) {
    const fs::path dir = temp_dir("migrate");
    const std::string path = (dir / "v6.db").string();
    {
        ResultStore old(path, 6);
        old.db().exec(
            "INSERT INTO experiment(name) VALUES ('e');"
            "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, "
            "compiler, flags, cpu_model, cores, governor, hostname, threads, shard) "
            "VALUES ('u', 1, 'h', '{}', 't', 'g', 'c', 'f', 'cpu', 1, 'gov', 'host', 1, '');"
            "INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) "
            "VALUES ('s', 'scene', '{}', '{}', 1, 2, 1, '{}');"
            "INSERT INTO config(structure, params) VALUES ('bf', '{}');"
            "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
            "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
            "raycast_ns_mad) VALUES (1, 'k', 1, 1, 0, 't', 1, 1, 1, 1, 4, 2, 10, 0, 100, 0);"
            // An exact frame, and one with 1 missed, 2 extra and 1 duplicate among 10 hits.
            "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, "
            "missed, extra, duplicate, n_t, n_rb, n_tp, memory_bytes, sah_cost, stats) VALUES "
            "(1, 1, 0, 0, 0, 0, 5, 1, 1, 6, 0, 0, 0, 1, 1, 1, 1, NULL, '{}'),"
            "(1, 2, 0, 0, 0, 0, 5, 1, 1, 10, 1, 2, 1, 1, 1, 1, 1, NULL, '{}');");
    }
    const auto check = [](Database& db) {
        Statement s = db.prepare(
            "SELECT returned, correct, relevant, n_ro, n_ro_hits FROM frame WHERE cell_id = 1 ORDER BY frame");
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 6);
        EXPECT_EQ(s.int64(1), 6);
        EXPECT_EQ(s.int64(2), 6);
        EXPECT_EQ(s.int64(3) + s.int64(4), 0);
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 9);  // distinct objects reported
        EXPECT_EQ(s.int64(1), 7);  // of those, not clearly missed
        EXPECT_EQ(s.int64(2), 8);  // and the missed one
        EXPECT_EQ(s.int64(3) + s.int64(4), 0);
    };
    {
        auto db = open_read_only(path);  // a migrated copy in memory
        check(*db);
    }
    {
        Database file(path, true);
        EXPECT_EQ(count(file, "PRAGMA user_version"), 6);  // reading left the file alone
    }
    {
        ResultStore store(path);  // migrated on open for writing
        EXPECT_EQ(count(store.db(), "PRAGMA user_version"), 7);
        EXPECT_EQ(latest_schema_version(), 7);
        check(store.db());
    }
    fs::remove_all(dir);
}

TEST(AccuracyColumns, ARunsFramesRoundTripThroughTheStoreAndMerge) {
    const fs::path dir = temp_dir("roundtrip");
    const Recording scene = test::with_shapes(test::generated_scene("irregular", 400, 3, 5), 9);
    // The candidate level on shapes: precision below 1, recall 1; the shape level runs the narrow
    // phase (n_ro > 0).
    std::vector<SimulationResult> results;
    for (const char* level : {"candidates", "shapes"})
        results.push_back(simulate(scene, find_structure("ug"), {{"query", level}}));
    ASSERT_GT(results[1].frames.back().counters.n_ro, 0u);
    ASSERT_LT(results[0].frames.back().correct, results[0].frames.back().returned);

    const Experiment e = parse_experiment(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "ug"}]})",
                                          "roundtrip", ".");
    const std::string a = (dir / "a.db").string(), b = (dir / "b.db").string();
    {
        ResultStore store(a);
        const std::int64_t ex = store.experiment_id(e);
        const std::int64_t run = store.begin_run(ex, RunInfo::current(1, "", e));
        for (std::size_t i = 0; i < results.size(); ++i) {
            Cell c = e.plan[0];
            c.key += std::to_string(i);
            ASSERT_TRUE(store.store_cell(run, ex, c, e.scenes[0], scene, recording_hash(scene), results[i]));
        }
    }
    {
        ResultStore merged(b);
        auto in = open_read_only(a);
        EXPECT_EQ(merge_into(merged, *in).cells, 2u);
    }
    for (const std::string& path : {a, b}) {
        auto db = open_read_only(path);
        for (std::size_t i = 0; i < results.size(); ++i) {
            Statement s = db->prepare(
                "SELECT frame.frame, returned, correct, relevant, n_ro, n_ro_hits FROM frame JOIN cell ON cell.id = "
                "frame.cell_id WHERE cell.cell_key LIKE '%' || ? ORDER BY frame.frame");
            s.bind(1, std::to_string(i));
            std::size_t n = 0;
            while (s.step()) {
                const FrameResult& f = results[i].frames.at(n++);
                EXPECT_EQ(s.int64(0), f.frame);
                EXPECT_EQ(std::uint64_t(s.int64(1)), f.returned) << path;
                EXPECT_EQ(std::uint64_t(s.int64(2)), f.correct) << path;
                EXPECT_EQ(std::uint64_t(s.int64(3)), f.relevant) << path;
                EXPECT_EQ(std::uint64_t(s.int64(4)), f.counters.n_ro) << path;
                EXPECT_EQ(std::uint64_t(s.int64(5)), f.counters.n_ro_hits) << path;
            }
            EXPECT_EQ(n, results[i].frames.size()) << path;
        }
    }
    fs::remove_all(dir);
}

}  // namespace
}  // namespace rcb

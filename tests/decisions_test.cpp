// Whether two runs make the same decisions (runner/decisions.h, `rcbench compare --decisions`), on
// two hand-made databases: one scene whose best structures differ by a tie, one where they truly
// differ, and configurations that agree and tie.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "runner/decisions.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// One repetition of a cell: every measured frame takes `cast` ns to ray cast and `update` ns to
/// update.
struct Rep {
    std::string scene, structure, params;
    int repetition;
    std::int64_t cast, update;
};

/// A results database holding one run of `reps`, three measured frames per cell and one warm-up
/// frame that no figure may read.
void write_run(const std::string& path, const std::vector<Rep>& reps) {
    ResultStore store(path);
    Database& db = store.db();
    db.exec(
        "INSERT INTO experiment(name) VALUES ('decisions');"
        "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, compiler, "
        "flags, cpu_model, cores, governor, hostname, threads, shard) VALUES ('" +
        path + "', 1, 'h', '{}', 't', 'g', 'c', 'f', 'cpu', 1, 'gov', 'host', 1, '')");
    for (const Rep& r : reps) {
        // The scene's hash is its name, the same in both databases: scenes match by content.
        db.prepare(
              "INSERT OR IGNORE INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) "
              "VALUES (?, ?, '{}', '{}', 10, 4, 10, '{}')")
            .bind_all(r.scene, r.scene)
            .run();
        db.prepare("INSERT OR IGNORE INTO config(structure, params) VALUES (?, ?)")
            .bind_all(r.structure, r.params)
            .run();
        db.prepare(
              "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
              "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
              "raycast_ns_mad) VALUES (1, ?, (SELECT id FROM scene WHERE hash = ?), (SELECT id FROM config WHERE "
              "structure = ? AND params = ?), ?, 't', 10, 1, 0, 0, 0, 4, ?, 0, ?, 0)")
            .bind_all(r.scene + r.structure + r.params + std::to_string(r.repetition), r.scene, r.structure, r.params,
                      std::int64_t(r.repetition), double(r.update), double(r.cast))
            .run();
        const std::int64_t cell = db.last_insert_id();
        for (std::int64_t frame = 0; frame < 4; ++frame) {
            const bool warmup = frame == 0;  // a warm-up frame 100 times slower
            db.prepare(
                  "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, "
                  "hits, missed, extra, duplicate, n_t, n_rb, n_tp, memory_bytes, stats) VALUES (?, ?, ?, 0, 0, 0, "
                  "10, ?, ?, 0, 0, 0, 0, 0, 0, 0, 0, '{}')")
                .bind_all(cell, frame, std::int64_t(warmup), r.update * (warmup ? 100 : 1), r.cast * (warmup ? 100 : 1))
                .run();
        }
    }
}

/// Run A and run B. Per-frame times (update + ray cast):
///   scene "tied":  A: ug c=1 100, ug c=2 130, bf 103 (picks ug)  B: ug c=1 102, ug c=2 140, bf 100 (picks bf)
///                  structures tie (A puts bf 3% above ug, B puts ug 2% above bf); ug's c=1 agrees.
///   scene "split": A: bf 100, ug c=1 150, ug c=2 153 (picks bf)   B: bf 120, ug c=1 104, ug c=2 100 (picks ug)
///                  structures differ (50% in A, 20% in B); ug's configurations tie (2% in A, 4% in B).
/// A's bf on "split" has two repetitions: ray casts 60 and 90, updates 30 and 50; fit's default
/// reading takes the fastest ray cast and the median update, 60 + 40 = 100 (the median of both,
/// 75 + 40 = 115, would put the gap in A at 30.4%). A's ug c=3 on "tied", 50, is not in B: no
/// decision may read it.
void write_runs(const std::string& a, const std::string& b) {
    const std::string c1 = R"({"cell_size":1.0})", c2 = R"({"cell_size":2.0})", c3 = R"({"cell_size":3.0})";
    write_run(a, {{"tied", "ug", c1, 0, 60, 40},
                  {"tied", "ug", c2, 0, 90, 40},
                  {"tied", "ug", c3, 0, 10, 40},
                  {"tied", "bf", "{}", 0, 63, 40},
                  {"split", "bf", "{}", 0, 60, 30},
                  {"split", "bf", "{}", 1, 90, 50},
                  {"split", "ug", c1, 0, 110, 40},
                  {"split", "ug", c2, 0, 113, 40}});
    write_run(b, {{"tied", "ug", c1, 0, 62, 40},
                  {"tied", "ug", c2, 0, 100, 40},
                  {"tied", "bf", "{}", 0, 60, 40},
                  {"split", "bf", "{}", 0, 80, 40},
                  {"split", "ug", c1, 0, 64, 40},
                  {"split", "ug", c2, 0, 60, 40}});
}

TEST(Decisions, ATieAndARealDisagreementPerSceneAndPerStructure) {
    const test::TempDir dir("decisions");
    const std::string a = dir.file("a.db"), b = dir.file("b.db");
    write_runs(a, b);
    Database da(a, true), db(b, true);
    const Decisions d = compare_decisions(da, 1, db, 1, 0.05);
    EXPECT_EQ(d.shared_cells, 6u);
    ASSERT_EQ(d.structures.size(), 2u);  // sorted by scene: "split", "tied"
    const Decision& split = d.structures[0];
    EXPECT_EQ(split.scene, "split");
    EXPECT_EQ(split.pick_a, "bf");
    EXPECT_EQ(split.pick_b, "ug");
    EXPECT_EQ(split.verdict, "differ");
    EXPECT_NEAR(split.gap_a, 0.50, 1e-12);
    EXPECT_NEAR(split.gap_b, 0.20, 1e-12);
    const Decision& tied = d.structures[1];
    EXPECT_EQ(tied.pick_a, "ug");
    EXPECT_EQ(tied.pick_b, "bf");
    EXPECT_EQ(tied.verdict, "tie");
    EXPECT_NEAR(tied.gap_a, 0.03, 1e-12);
    EXPECT_NEAR(tied.gap_b, 0.02, 1e-12);
    // bf has one configuration: no decision. ug on both scenes has two shared ones.
    ASSERT_EQ(d.configurations.size(), 2u);
    EXPECT_EQ(d.configurations[0].structure, "ug");
    EXPECT_EQ(d.configurations[0].verdict, "tie");
    EXPECT_NEAR(d.configurations[0].gap_a, 0.02, 1e-12);
    EXPECT_NEAR(d.configurations[0].gap_b, 0.04, 1e-12);
    EXPECT_EQ(d.configurations[1].verdict, "same");
    EXPECT_EQ(agreement(d.structures), (std::pair<std::size_t, std::size_t>{0, 1}));
    EXPECT_EQ(agreement(d.configurations), (std::pair<std::size_t, std::size_t>{1, 2}));
    // Under a 2.5% tie, "tied" is a disagreement too (A's 3%).
    EXPECT_EQ(compare_decisions(da, 1, db, 1, 0.025).structures[1].verdict, "differ");
}

TEST(Decisions, CompareDecisionsPrintsTheSharesAndGaps) {
    const test::TempDir dir("decisions", "cli");
    const std::string a = dir.file("a.db"), b = dir.file("b.db");
    write_runs(a, b);
    const ::test::Outcome out = ::test::run_process({RCBENCH_BINARY, "compare", "--decisions", a, b});
    ASSERT_EQ(out.code, 0) << out.err;
    const auto has = [&](const std::string& text) { return out.out.find(text) != std::string::npos; };
    EXPECT_TRUE(has("best structure: 0 of 2 scenes agree, 1 of 2 agree or tie")) << out.out;
    EXPECT_TRUE(has("best configuration: 1 of 2 (scene, structure) agree, 2 of 2 agree or tie")) << out.out;
    for (const char* gap : {"50.0%", "20.0%", "3.0%", "2.0%", "4.0%"}) EXPECT_TRUE(has(gap)) << gap << '\n' << out.out;
    EXPECT_TRUE(has("ug cell_size=2")) << out.out;  // the pick B makes on "split"

    const ::test::Outcome json = ::test::run_process({RCBENCH_BINARY, "compare", "--decisions", a, b, "--json"});
    ASSERT_EQ(json.code, 0) << json.err;
    const nlohmann::json j = nlohmann::json::parse(json.out);
    EXPECT_EQ(j["best_structure"]["agree"], 0);
    EXPECT_EQ(j["best_structure"]["agree_or_tie"], 1);
    EXPECT_EQ(j["best_configuration"]["agree_or_tie"], 2);
    EXPECT_NEAR(j["best_structure"]["rows"][0]["gap_a"].get<double>(), 0.5, 1e-12);

    // The same run twice says nothing: refused. So is a mix with the per-cell comparison's options.
    const ::test::Outcome same = ::test::run_process({RCBENCH_BINARY, "compare", "--decisions", a, a});
    EXPECT_EQ(same.code, 2);
    EXPECT_NE(same.err.find("the same run"), std::string::npos) << same.err;
    const ::test::Outcome mixed =
        ::test::run_process({RCBENCH_BINARY, "compare", "--decisions", a, b, "--baseline", "1"});
    EXPECT_EQ(mixed.code, 2);
    const ::test::Outcome neither = ::test::run_process({RCBENCH_BINARY, "compare", a, "--candidate", "1"});
    EXPECT_EQ(neither.code, 2);
    EXPECT_NE(neither.err.find("--baseline is required"), std::string::npos) << neither.err;
}

}  // namespace
}  // namespace rcb

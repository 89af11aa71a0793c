// The noise floor: repetition-major plans, the machine state stored with each cell, slow cells
// flagged against the run's median, repeatability per structure, and the state surviving a merge.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "analysis/noise.h"
#include "analysis/report.h"
#include "runner/compare.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

std::int64_t count(Database& db, const std::string& sql) {
    Statement s = db.prepare(sql);
    return s.step() ? s.int64(0) : -1;
}

const char* kThree = R"({"name": "noise", "frames": 3, "rays_per_frame": 200, "repetitions": 3,
    "scenes": [{"kind": "uniform", "objects": 300}, {"kind": "irregular", "objects": 300}],
    "structures": [{"name": "bf"}, {"name": "ug"}]})";

TEST(NoisePlan, RepetitionROfEveryCellRunsBeforeRepetitionROnePlusOneOfAny) {
    const Experiment e = parse_experiment(kThree, "noise.json", ".");
    ASSERT_EQ(e.plan.size(), 12u);  // 2 scenes × 2 configurations × 3 repetitions
    for (std::size_t i = 0; i < e.plan.size(); ++i) EXPECT_EQ(e.plan[i].repetition, i / 4) << i;
    // Within a repetition, scene by scene, so consecutive cells share a scene load.
    EXPECT_EQ(e.plan[0].scene, 0u);
    EXPECT_EQ(e.plan[1].scene, 0u);
    EXPECT_EQ(e.plan[2].scene, 1u);
    // Shards still take every N-th cell, so each shard spreads its repetitions over its run too.
    const std::vector<Cell> shard = shard_plan(e, 2, 3);
    ASSERT_EQ(shard.size(), 4u);
    for (std::size_t i = 1; i < shard.size(); ++i) EXPECT_LE(shard[i - 1].repetition, shard[i].repetition);
}

TEST(NoiseState, TheCalibrationLoopTakesAFewMillisecondsAndTheLoadIsRead) {
    const MachineState m = sample_machine_state();
    EXPECT_GT(m.calibration_ns, 1e4);  // at least 10 µs: the loop was not optimised away
    EXPECT_LT(m.calibration_ns, 1e8);  // well under 100 ms even on a busy machine
    if (fs::exists("/proc/loadavg")) {
        EXPECT_GE(m.load_1m, 0.0);
    }
}

TEST(NoiseFloor, RepeatabilityIsTheMedianRelativeDeviationFromEachCellsMedian) {
    const std::vector<RepeatSample> samples = {
        {"ug", "a", 100, 10, false}, {"ug", "a", 110, 10, true}, {"ug", "a", 90, 10, false},
        {"ug", "b", 200, 0, false},  {"ug", "b", 220, 0, false}, {"ug", "c", 500, 0, true},  // c: one repetition
        {"bf", "x", 300, 5, false},
    };
    const std::vector<StructureNoise> n = repeatability(samples);
    ASSERT_EQ(n.size(), 2u);
    EXPECT_EQ(n[0].structure, "bf");
    EXPECT_TRUE(std::isnan(n[0].raycast));  // no repeated cell: no figure rather than a made-up 0
    EXPECT_EQ(n[0].cells, 0u);
    EXPECT_EQ(n[1].structure, "ug");
    EXPECT_EQ(n[1].cells, 2u);
    EXPECT_EQ(n[1].repetitions, 5u);
    EXPECT_EQ(n[1].slow, 2u);
    // a: deviations 0, 0.1, 0.1; b: 10/210 twice → median of {0, 0.0476, 0.0476, 0.1, 0.1}.
    EXPECT_NEAR(n[1].raycast, 10.0 / 210.0, 1e-12);
    EXPECT_NEAR(n[1].update, 0.0, 1e-12);  // a's update repeats exactly; b has none
    EXPECT_EQ(noise_text(n[1].raycast), "4.8%");
    EXPECT_EQ(noise_text(n[0].raycast), "-");
}

TEST(NoiseFloor, EveryCellStoresItsStateAndCellsTenPercentSlowAreFlagged) {
    const test::TempDir temp("noise", "flag");
    const fs::path& dir = temp.path();
    const std::string db_path = (dir / "r.db").string();
    const Experiment e = parse_experiment(kThree, "noise.json", dir.string());
    RunOptions o;
    o.db = db_path;
    const RunOutcome out = run_experiment(e, "noise.json", o);
    ASSERT_TRUE(out.finished);
    ResultStore store(db_path);
    Database& db = store.db();
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell_state"), 12);
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell_state WHERE calibration_ns > 0"), 12);
    // Stored in plan order: repetition-major.
    {
        Statement s = db.prepare("SELECT repetition FROM cell ORDER BY id");
        std::int64_t last = 0;
        while (s.step()) EXPECT_GE(s.int64(0), last), last = s.int64(0);
    }
    // A synthetic machine: eleven cells at 1.00 ms, one at 1.15 ms (15% slow) and one value set
    // just under the 10% limit must stay unflagged.
    db.exec("UPDATE cell_state SET calibration_ns = 1.0e6");
    db.exec("UPDATE cell_state SET calibration_ns = 1.15e6 WHERE cell_id = (SELECT min(cell_id) FROM cell_state)");
    db.exec("UPDATE cell_state SET calibration_ns = 1.09e6 WHERE cell_id = (SELECT max(cell_id) FROM cell_state)");
    EXPECT_EQ(store.flag_slow_cells(out.run), 1u);
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell_state WHERE slow = 1"), 1);
    EXPECT_EQ(count(db, "SELECT slow FROM cell_state WHERE cell_id = (SELECT min(cell_id) FROM cell_state)"), 1);
    // The listing view shows the flag; the summaries, the noise floor and the slow-cell list agree.
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell_summary WHERE slow = 1"), 1);
    std::size_t flagged = 0;
    for (const CellSummary& c : cell_summaries(db, out.run)) flagged += c.slow;
    EXPECT_EQ(flagged, 1u);
    const NoiseFloor n = noise_floor(db, out.run);
    EXPECT_EQ(n.cells, 12u);
    EXPECT_EQ(n.with_state, 12u);
    EXPECT_EQ(n.slow, 1u);
    ASSERT_EQ(n.structures.size(), 2u);
    for (const StructureNoise& s : n.structures) {
        EXPECT_EQ(s.cells, 2u) << s.structure;  // two scenes, each cell repeated three times
        EXPECT_EQ(s.repetitions, 6u) << s.structure;
        EXPECT_TRUE(std::isfinite(s.raycast)) << s.structure;
        EXPECT_GE(s.raycast, 0.0) << s.structure;
    }
    const std::vector<SlowCell> slow = slow_cells(db, out.run);
    ASSERT_EQ(slow.size(), 1u);
    EXPECT_EQ(slow[0].repetition, 0);  // the first cell measured
    EXPECT_NEAR(slow[0].calibration_ratio, 1.15, 1e-9);
    // compare counts the flagged repetition on its side.
    std::size_t slow_in_compare = 0;
    for (const Comparison& c : compare_runs(db, std::to_string(out.run), std::to_string(out.run), "raycast", 0.05))
        slow_in_compare += c.baseline_slow;
    EXPECT_EQ(slow_in_compare, 1u);

    // The report marks the flagged cell in Table 6.2 and prints the noise floor beside the model.
    {
        const std::string html_path = (dir / "r.html").string();
        write_report(db, out.run, html_path);
        std::ifstream in(html_path);
        const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        EXPECT_NE(html.find("a repetition was measured on a slow machine"), std::string::npos);
        EXPECT_NE(html.find(") *</td>"), std::string::npos);
        EXPECT_NE(html.find("repeatability (ray cast)"), std::string::npos);
        EXPECT_NE(html.find("1 were measured while the calibration loop ran more than 10%"), std::string::npos);
    }
    // A merge carries the state and the flags.
    const std::string merged = (dir / "merged.db").string();
    {
        ResultStore m(merged);
        Database in(db_path, true);
        merge_into(m, in);
        EXPECT_EQ(count(m.db(), "SELECT count(*) FROM cell_state"), 12);
        EXPECT_EQ(count(m.db(), "SELECT count(*) FROM cell_state WHERE slow = 1"), 1);
    }
}

TEST(NoiseFloor, ADatabaseFromBeforeTheMachineStateMigratesAndItsCellsHaveNoState) {
    const test::TempDir temp("noise", "old");
    const fs::path& dir = temp.path();
    const std::string db_path = (dir / "old.db").string();
    const int before = latest_schema_version() - 1;
    {
        ResultStore old(db_path, before);
        old.db().exec(
            "INSERT INTO experiment(name) VALUES ('e');"
            "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, "
            "compiler, "
            "flags, cpu_model, cores, governor, hostname, threads, shard) "
            "VALUES ('u', 1, 'h', '{}', 't', 'g', 'c', 'f', 'cpu', 1, 'gov', 'host', 1, '');"
            "INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) "
            "VALUES ('s', 'scene', '{}', '{}', 1, 1, 1, '{}');"
            "INSERT INTO config(structure, params) VALUES ('bf', '{}');");
        for (int rep = 0; rep < 2; ++rep)
            old.db().exec(
                "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
                "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
                "raycast_ns_mad) VALUES (1, 'k" +
                std::to_string(rep) + "', 1, 1, " + std::to_string(rep) + ", 't', 1, 1, 1, 1, 0, 1, 10, 0, " +
                std::to_string(100 + 20 * rep) + ", 0)");
    }
    ResultStore store(db_path);  // migrated on open
    EXPECT_EQ(count(store.db(), "PRAGMA user_version"), latest_schema_version());
    EXPECT_EQ(count(store.db(), "SELECT count(*) FROM cell_summary WHERE slow IS NULL"), 2);
    const NoiseFloor n = noise_floor(store.db(), 1);
    EXPECT_EQ(n.with_state, 0u);
    ASSERT_EQ(n.structures.size(), 1u);
    EXPECT_NEAR(n.structures[0].raycast, 10.0 / 110.0, 1e-12);  // 100 and 120 about their median 110
    EXPECT_EQ(store.flag_slow_cells(1), 0u);
}

}  // namespace
}  // namespace rcb

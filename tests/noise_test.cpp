// The noise floor: repetition-major plans, the machine state stored with each cell, slow cells
// flagged against the run's median, repeatability per structure, and the state surviving a merge.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>

#include "analysis/cost_model.h"
#include "analysis/noise.h"
#include "analysis/report.h"
#include "runner/compare.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

using test::count;

const char* kThree = R"({"name": "noise", "frames": 3, "rays_per_frame": 200, "repetitions": 3,
    "scenes": [{"generator": "uniform", "objects": 300}, {"generator": "irregular", "objects": 300}],
    "structures": [{"name": "bf"}, {"name": "ug"}]})";

TEST(NoisePlan, RepetitionROfEveryCellRunsBeforeRepetitionROnePlusOneOfAny) {
    const Experiment e = parse_experiment(kThree, "noise.json", ".");
    ASSERT_EQ(e.plan.size(), 12u);  // 2 scenes × 2 configurations × 3 repetitions
    for (std::size_t i = 0; i < e.plan.size(); ++i) EXPECT_EQ(e.plan[i].repetition, i / 4) << i;
    // Shards still take every N-th cell, so each shard spreads its repetitions over its run too.
    const std::vector<Cell> shard = shard_plan(e, 2, 3);
    ASSERT_EQ(shard.size(), 4u);
    for (std::size_t i = 1; i < shard.size(); ++i) EXPECT_LE(shard[i - 1].repetition, shard[i].repetition);
}

TEST(NoisePlan, EachRepetitionVisitsEveryCellOnceInItsOwnSeededOrder) {
    // 6 scenes × 5 configurations: 30! orders of a repetition's cells, so two repetitions in the
    // same order would be a coincidence.
    const char* text = R"({"name": "order", "frames": 2, "repetitions": 4,
        "scenes": [{"generator": "uniform", "objects": [100, 200, 300, 400, 500, 600]}],
        "structures": [{"name": "ug", "params": {"density": [1, 2, 4, 8, 16]}}]})";
    const Experiment e = parse_experiment(text, "order.json", ".");
    ASSERT_EQ(e.plan.size(), 4u * 30u);
    std::vector<std::vector<std::pair<std::size_t, std::size_t>>> orders(4);
    for (const Cell& c : e.plan) {
        orders[c.repetition].emplace_back(c.scene, c.config);
        EXPECT_EQ(c.key, cell_key(e, c.scene, c.config, c.repetition));
    }
    for (std::size_t r = 0; r < 4; ++r) {
        std::set<std::pair<std::size_t, std::size_t>> seen(orders[r].begin(), orders[r].end());
        EXPECT_EQ(seen.size(), 30u) << r;  // every cell once
        // The scenes' cells interleave: a slow stretch of the machine falls on many scenes. In
        // blocks of one scene each, the scene would change 5 times in the repetition's 30 cells.
        std::size_t changes = 0;
        for (std::size_t i = 1; i < orders[r].size(); ++i) changes += orders[r][i].first != orders[r][i - 1].first;
        EXPECT_GT(changes, 15u) << r;
    }
    std::set<std::vector<std::pair<std::size_t, std::size_t>>> distinct(orders.begin(), orders.end());
    EXPECT_EQ(distinct.size(), 4u);
    // The same file gives the same order (the seed is the file's hash).
    const Experiment again = parse_experiment(text, "order.json", ".");
    for (std::size_t i = 0; i < e.plan.size(); ++i) EXPECT_EQ(again.plan[i].key, e.plan[i].key) << i;
}

TEST(NoisePlan, RepetitionsAreAddedWhereTheIntervalIsWideUpToTheCap) {
    const test::TempDir temp("noise", "added");
    // Made-up ray-cast times (RunOptions::timing), so the verdict does not follow the machine:
    // a structure's k-th simulated cell takes 100 µs · (1 + k·step) per frame.
    const auto run = [&](const std::string& name, double step) {
        const std::string text = R"({"name": "added", "frames": 3, "rays_per_frame": 100, "repetitions": 2,
            "max_repetitions": 4, "repeat_interval": 0.05,
            "scenes": [{"generator": "uniform", "objects": 200}, {"generator": "irregular", "objects": 200}],
            "structures": [{"name": "bf"}, {"name": "ug"}]})";
        const Experiment e = parse_experiment(text, name, temp.path().string());
        EXPECT_EQ(e.plan.size(), 8u);
        RunOptions o;
        o.db = (temp.path() / (name + ".db")).string();
        auto calls = std::make_shared<std::map<std::string, int>>();
        o.timing = [calls, step](SimulationResult& r) {
            const int k = (*calls)[r.structure]++;
            for (FrameResult& f : r.frames) {
                f.raycast_ns = std::uint64_t(100e3 * (1 + k * step));
                f.update_ns = 1000;
            }
        };
        const RunOutcome out = run_experiment(e, name, o);
        EXPECT_TRUE(out.finished);
        ResultStore store(o.db);
        return std::pair(out, count(store.db(), "SELECT count(*) FROM cell"));
    };
    // 10% apart per repetition: the interval stays wider than ±5%, so every cell reaches the cap.
    const auto [all, all_cells] = run("wide", 0.1);
    EXPECT_EQ(all.added, 8u);
    EXPECT_EQ(all_cells, 16);
    // The same time in every repetition: a point; nothing is added.
    const auto [none, none_cells] = run("narrow", 0.0);
    EXPECT_EQ(none.added, 0u);
    EXPECT_EQ(none_cells, 8);
}

TEST(NoisePlan, InterleavedCellsAreStoredWithTheirOwnScenes) {
    // Each scene is loaded once and kept while the repetition moves between scenes: every stored
    // cell must name the scene its key was planned for, and the content hash of that scene.
    const test::TempDir temp("noise", "interleaved");
    const std::string text = R"({"name": "inter", "frames": 2, "rays_per_frame": 50, "repetitions": 2,
        "scenes": [{"generator": "uniform", "objects": 150}, {"generator": "irregular", "objects": 250},
                   {"generator": "clusters", "objects": 350}],
        "structures": [{"name": "bf"}, {"name": "ug", "params": {"density": [1, 4]}}]})";
    const Experiment e = parse_experiment(text, "inter.json", temp.path().string());
    RunOptions o;
    o.db = (temp.path() / "inter.db").string();
    const RunOutcome out = run_experiment(e, "inter.json", o);
    ASSERT_TRUE(out.finished);
    EXPECT_EQ(out.mismatches, 0u);
    ResultStore store(o.db);
    for (const Cell& c : e.plan) {
        const std::string where =
            "SELECT count(*) FROM cell JOIN scene ON scene.id = cell.scene_id WHERE cell_key = '" + c.key +
            "' AND scene.name = '" + e.scenes[c.scene].name +
            "' AND cell.objects = " + std::to_string(150 + 100 * c.scene);
        EXPECT_EQ(count(store.db(), where), 1) << c.key;
    }
    EXPECT_EQ(count(store.db(), "SELECT count(DISTINCT hash) FROM scene"), 3);
}

TEST(NoisePlan, MaxRepetitionsBelowRepetitionsIsRefused) {
    test::expect_input_error(
        [] {
            parse_experiment(R"({"repetitions": 3, "max_repetitions": 2, "scenes": [{"preset": "uni-s"}],
                                 "structures": [{"name": "bf"}]})",
                             "cap.json", ".");
        },
        "cap.json: max_repetitions: expected an integer in 3..1000");
}

TEST(NoiseState, TheCalibrationLoopIsNotOptimisedAwayAndTheLoadIsRead) {
    const MachineState m = sample_machine_state();
    // 750,000 dependent multiply-adds take at least 10 µs on any CPU: less, and the loop was
    // optimised away. No upper bound: the loop's wall time is the machine's load, which is what
    // it measures (a niced test beside two busy processes waits many times its work).
    EXPECT_GT(m.calibration_ns, 1e4);
    EXPECT_GT(m.memory_ns, 0);
    if (fs::exists("/proc/loadavg")) {
        EXPECT_GE(m.load_1m, 0.0);
    }
}

TEST(NoiseFloor, RepeatabilityIsTheSpreadOfTheFirstTwoRepetitionsMedianAndP90OverCells) {
    const std::vector<RepeatSample> samples = {
        {"ug", "a", 100, 10, false, 0}, {"ug", "a", 110, 10, true, 1},
        {"ug", "a", 300, 10, false, 2},  // an added repetition: not part of the two-run figure
        {"ug", "b", 200, 0, false, 0},  {"ug", "b", 260, 0, false, 1},
        {"ug", "c", 500, 0, true, 0},  // c: one repetition
        {"bf", "x", 300, 5, false, 0},
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
    // a: (110 − 100) / 105; b: (260 − 200) / 230. Median and 90th percentile of the two.
    const double a = 10.0 / 105.0, b = 60.0 / 230.0;
    EXPECT_NEAR(n[1].raycast, (a + b) / 2, 1e-12);
    EXPECT_NEAR(n[1].raycast_p90, a + 0.9 * (b - a), 1e-12);
    EXPECT_NEAR(n[1].update, 0.0, 1e-12);  // a's update repeats exactly; b has none
    // The frame is update + ray cast: a (120 − 110) / 115, b as the ray cast (no update).
    const double fa = 10.0 / 115.0;
    EXPECT_NEAR(n[1].frame, (fa + b) / 2, 1e-12);
    EXPECT_NEAR(n[1].frame_p90, fa + 0.9 * (b - fa), 1e-12);
    EXPECT_EQ(noise_text(n[1].raycast), "17.8%");
    EXPECT_EQ(noise_text(n[1].raycast, n[1].raycast_p90), "17.8% / 24.4%");
    EXPECT_EQ(noise_text(n[0].raycast), "-");
    EXPECT_EQ(noise_text(n[0].raycast, n[0].raycast_p90), "-");
}

/// kThree run twice, into a.db and b.db of `dir`: two independent runs to compare.
struct TwoRuns {
    explicit TwoRuns(const fs::path& dir) {
        const Experiment e = parse_experiment(kThree, "noise.json", dir.string());
        for (const char* name : {"a.db", "b.db"}) {
            RunOptions o;
            o.db = (dir / name).string();
            const RunOutcome out = run_experiment(e, "noise.json", o);
            finished = finished && out.finished;
            runs.push_back(out.run);
            stores.push_back(std::make_unique<ResultStore>(o.db));
        }
    }
    bool finished = true;
    std::vector<std::unique_ptr<ResultStore>> stores;
    std::vector<std::int64_t> runs;
};

/// Two finished runs, in a folder named after the test: databases `a` and `b`, run ids `runs`.
class BetweenRuns : public ::testing::Test {
protected:
    void SetUp() override { ASSERT_TRUE(two_.finished); }

    const test::TempDir temp_{"noise", ::testing::UnitTest::GetInstance()->current_test_info()->name()};
    const TwoRuns two_{temp_.path()};
    Database& a = two_.stores[0]->db();
    Database& b = two_.stores[1]->db();
    const std::vector<std::int64_t>& runs = two_.runs;
};

TEST_F(BetweenRuns, BetweenRunsComparesEachRunsMedianOverRepetitionsOfTheCellsBothHold) {
    // Made-up medians: a measures 100 everywhere (one repetition of bf an outlier, which the median
    // over repetitions drops), b measures bf at 120; b lacks ug on the irregular scene.
    const std::string bf = "(SELECT id FROM config WHERE structure = 'bf')";
    a.exec("UPDATE cell SET raycast_ns_median = 100, update_ns_median = 50");
    a.exec("UPDATE cell SET raycast_ns_median = 1000 WHERE repetition = 2 AND config_id = " + bf);
    b.exec("UPDATE cell SET raycast_ns_median = 100, update_ns_median = 50");
    b.exec("UPDATE cell SET raycast_ns_median = 120, update_ns_median = 60 WHERE config_id = " + bf);
    b.exec(
        "UPDATE cell_state SET slow = 1 WHERE cell_id IN (SELECT id FROM cell WHERE repetition = 0 AND "
        "config_id = " +
        bf + ")");
    b.exec(
        "DELETE FROM cell WHERE config_id = (SELECT id FROM config WHERE structure = 'ug') AND scene_id = "
        "(SELECT id FROM scene WHERE name LIKE 'irregular%')");
    const std::vector<StructureNoise> n = between_runs(a, runs[0], b, runs[1]);
    ASSERT_EQ(n.size(), 2u);
    EXPECT_EQ(n[0].structure, "bf");
    EXPECT_EQ(n[0].cells, 2u);
    EXPECT_EQ(n[0].slow, 2u);  // both bf cells had a slow repetition in b
    EXPECT_NEAR(n[0].raycast, 20.0 / 110.0, 1e-12);
    EXPECT_NEAR(n[0].raycast_p90, 20.0 / 110.0, 1e-12);
    EXPECT_NEAR(n[0].update, 10.0 / 55.0, 1e-12);
    EXPECT_EQ(n[1].structure, "ug");
    EXPECT_EQ(n[1].cells, 1u);  // only the uniform scene is in both
    EXPECT_NEAR(n[1].raycast, 0.0, 1e-12);
    // The same run against itself: no spread at all.
    const std::vector<StructureNoise> self = between_runs(a, runs[0], a, runs[0]);
    for (const StructureNoise& s : self) EXPECT_NEAR(s.raycast_p90, 0.0, 1e-12) << s.structure;
}

// Another process only ever adds time. Run a's repetitions were each slowed, on different frames:
// no repetition is undisturbed, so its median over repetitions moves, yet every frame has one
// undisturbed measurement, which each frame's fastest keeps.
TEST_F(BetweenRuns, BetweenRunsByEachFramesFastestRepetitionLeavesOutTimeAddedByLoad) {
    for (Database* db : {&a, &b}) db->exec("UPDATE frame SET raycast_ns = 100, update_ns = 50");
    a.exec(
        "UPDATE frame SET raycast_ns = 130, update_ns = 80 WHERE cell_id IN (SELECT id FROM cell WHERE repetition = "
        "2) OR (frame % 2 = 0 AND cell_id IN (SELECT id FROM cell WHERE repetition = 0)) OR (frame % 2 = 1 AND "
        "cell_id IN (SELECT id FROM cell WHERE repetition = 1))");
    a.exec("UPDATE cell SET raycast_ns_median = 130, update_ns_median = 80");
    b.exec("UPDATE cell SET raycast_ns_median = 100, update_ns_median = 50");
    const StructureNoise median = between_runs_pooled(a, runs[0], b, runs[1], OverRepetitions::median);
    EXPECT_EQ(median.structure, "all");
    EXPECT_EQ(median.cells, 4u);  // every cell of both structures, pooled
    EXPECT_NEAR(median.raycast_p90, 30.0 / 115.0, 1e-12);
    EXPECT_NEAR(median.update, 30.0 / 65.0, 1e-12);
    const StructureNoise fastest = between_runs_pooled(a, runs[0], b, runs[1], OverRepetitions::fastest);
    EXPECT_EQ(fastest.cells, 4u);
    EXPECT_NEAR(fastest.raycast_p90, 0.0, 1e-12);
    EXPECT_NEAR(fastest.update_p90, 0.0, 1e-12);
    for (const StructureNoise& s : between_runs(a, runs[0], b, runs[1], OverRepetitions::fastest))
        EXPECT_NEAR(s.raycast_p90, 0.0, 1e-12) << s.structure;

    // The fit reads the same: one observation per measured frame of a cell, at its fastest time;
    // with `median`, every repetition's frames as measured.
    const std::vector<FrameObservation> each = load_observations(a, runs[0], OverRepetitions::median);
    const std::vector<FrameObservation> least = load_observations(a, runs[0], OverRepetitions::fastest);
    ASSERT_FALSE(least.empty());
    EXPECT_EQ(each.size(), 3 * least.size());  // three repetitions of every cell
    for (const FrameObservation& f : least) {
        EXPECT_EQ(f.raycast_ns, 100);
        EXPECT_EQ(f.update_ns, 50);
    }
    EXPECT_TRUE(std::any_of(each.begin(), each.end(), [](const FrameObservation& f) { return f.raycast_ns == 130; }));
    // The counters are the repetitions' own: every repetition replays the same recording.
    for (std::size_t i = 0; i < least.size(); ++i) {
        EXPECT_EQ(least[i].n_t, each[i].n_t) << i;
        EXPECT_EQ(least[i].rays, each[i].rays) << i;
    }
}

// The cache state an update starts in can take time away: a repetition that found its lines
// still cached updates fast on every frame. Each frame's fastest takes that lucky repetition;
// fastest-cast keeps the fastest ray cast (only load adds time to it) and the frame's median update.
TEST_F(BetweenRuns, FastestCastReadsEachFramesFastestRayCastAndMedianUpdate) {
    for (Database* db : {&a, &b}) db->exec("UPDATE frame SET raycast_ns = 100, update_ns = 50");
    const auto repetition = [](int r) {
        return "cell_id IN (SELECT id FROM cell WHERE repetition = " + std::to_string(r) + ")";
    };
    // a: repetition 0 lucky on the update, repetition 1 slow on its even frames, repetition 2 slow
    // on the ray cast; each frame's median update stays 50.
    a.exec("UPDATE frame SET update_ns = 20 WHERE " + repetition(0));
    a.exec("UPDATE frame SET update_ns = 80 WHERE frame % 2 = 0 AND " + repetition(1));
    a.exec("UPDATE frame SET raycast_ns = 130 WHERE " + repetition(2));
    const StructureNoise fastest = between_runs_pooled(a, runs[0], b, runs[1], OverRepetitions::fastest);
    EXPECT_NEAR(fastest.update_p90, 30.0 / 35.0, 1e-12);
    EXPECT_NEAR(fastest.raycast_p90, 0.0, 1e-12);
    const StructureNoise mixed = between_runs_pooled(a, runs[0], b, runs[1], OverRepetitions::fastest_cast);
    EXPECT_EQ(mixed.cells, 4u);
    EXPECT_NEAR(mixed.update_p90, 0.0, 1e-12);
    EXPECT_NEAR(mixed.raycast_p90, 0.0, 1e-12);

    const std::vector<FrameObservation> least = load_observations(a, runs[0], OverRepetitions::fastest);
    const std::vector<FrameObservation> frames = load_observations(a, runs[0]);  // the default
    ASSERT_EQ(frames.size(), least.size());  // one observation per measured frame of a cell
    ASSERT_FALSE(frames.empty());
    for (std::size_t i = 0; i < frames.size(); ++i) {
        EXPECT_EQ(least[i].update_ns, 20) << i;
        EXPECT_EQ(frames[i].update_ns, 50) << i;
        EXPECT_EQ(frames[i].raycast_ns, 100) << i;
        EXPECT_EQ(frames[i].n_t, least[i].n_t) << i;
    }
    EXPECT_EQ(parse_repetitions("fastest-cast"), OverRepetitions::fastest_cast);
    EXPECT_FALSE(parse_repetitions("fastest_cast").has_value());
}

// A small update moves with the cache state it starts in, a large one repeats: the bands keep them
// apart. bf's cells update in 5 us in a and 8 us in b, ug's in 200 and 204 us; the ray cast is 100
// us everywhere. With the cells' figures put in the frames, every reading gives the same bands.
TEST_F(BetweenRuns, TheUpdateIsComparedBandByBandOfItsSize) {
    const std::string bf =
        "cell_id IN (SELECT cell.id FROM cell JOIN config ON config.id = cell.config_id WHERE "
        "config.structure = 'bf')";
    for (Database* db : {&a, &b}) db->exec("UPDATE frame SET raycast_ns = 100e3, update_ns = 200e3");
    a.exec("UPDATE frame SET update_ns = 5e3 WHERE " + bf);
    b.exec("UPDATE frame SET update_ns = 204e3 WHERE NOT " + bf);
    b.exec("UPDATE frame SET update_ns = 8e3 WHERE " + bf);
    for (Database* db : {&a, &b})
        db->exec(
            "UPDATE cell SET raycast_ns_median = 100e3, update_ns_median = (SELECT max(update_ns) FROM frame "
            "WHERE frame.cell_id = cell.id)");
    for (const OverRepetitions how :
         {OverRepetitions::median, OverRepetitions::fastest, OverRepetitions::fastest_cast}) {
        const std::vector<UpdateBand> bands = between_runs_by_update(a, runs[0], b, runs[1], how);
        ASSERT_EQ(bands.size(), 4u);
        EXPECT_EQ(bands[0].from_ns, 0);
        EXPECT_EQ(bands[0].below_ns, 10e3);
        EXPECT_EQ(bands[3].from_ns, 100e3);
        EXPECT_TRUE(std::isinf(bands[3].below_ns));
        EXPECT_EQ(bands[0].cells, 2u);  // bf on both scenes: sqrt(5 * 8) = 6.3 us
        EXPECT_NEAR(bands[0].update_p90, 3.0 / 6.5, 1e-12);
        EXPECT_NEAR(bands[0].share, 13.0 / 213.0, 1e-12);
        for (const std::size_t empty : {1, 2}) {
            EXPECT_EQ(bands[empty].cells, 0u);
            EXPECT_TRUE(std::isnan(bands[empty].update_p90));
        }
        EXPECT_EQ(bands[3].cells, 2u);
        EXPECT_NEAR(bands[3].update, 4.0 / 202.0, 1e-12);
        EXPECT_NEAR(bands[3].share, 404.0 / 604.0, 1e-12);
    }
}

TEST(NoiseFloor, QuantilesInterpolateBetweenOrderStatistics) {
    EXPECT_TRUE(std::isnan(quantile({}, 0.5)));
    EXPECT_EQ(quantile({3, 1, 2}, 0.5), 2);
    EXPECT_EQ(quantile({4, 1, 2, 3}, 0.5), 2.5);
    EXPECT_NEAR(quantile({0, 10}, 0.9), 9, 1e-12);
    EXPECT_EQ(quantile({5}, 0.9), 5);
    EXPECT_EQ(relative_range({100, 110, 90}), 0.2);
    EXPECT_EQ(relative_range({100}), 0);
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
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell_state WHERE memory_ns > 0"), 12);
    // Stored in plan order: repetition-major.
    {
        Statement s = db.prepare("SELECT repetition FROM cell ORDER BY id");
        std::int64_t last = 0;
        while (s.step()) EXPECT_GE(s.int64(0), last), last = s.int64(0);
    }
    // A synthetic machine: eleven cells at 1.00 ms, one at 1.15 ms (15% slow) and one value set
    // just under the 10% limit must stay unflagged.
    db.exec("UPDATE cell_state SET calibration_ns = 1.0e6, memory_ns = 8.0e6");
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
        EXPECT_NE(html.find("1 were measured while the calibration loop or memory probe ran more than 10%"),
                  std::string::npos);
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
    // The memory probe flags on its own: the integer loop at its median, the probe 12.5% slow.
    db.exec("UPDATE cell_state SET memory_ns = 9.0e6 WHERE cell_id = (SELECT max(cell_id) FROM cell_state)");
    EXPECT_EQ(store.flag_slow_cells(out.run), 2u);
    EXPECT_EQ(count(db, "SELECT slow FROM cell_state WHERE cell_id = (SELECT max(cell_id) FROM cell_state)"), 1);
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
    EXPECT_NEAR(n.structures[0].raycast, 20.0 / 110.0, 1e-12);  // 100 and 120: (120 − 100) / 110
    EXPECT_EQ(store.flag_slow_cells(1), 0u);
}

}  // namespace
}  // namespace rcb

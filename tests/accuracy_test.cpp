// Speed against accuracy: the per-frame accuracy columns of the results database (schema
// version 7) and their migration, read back and merged.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include "analysis/charts.h"
#include "core/base/error.h"
#include "accel/narrow/narrow_phase.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"
#include "tuner/accuracy.h"
#include "tuner/advise.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

using test::count;

TEST(AccuracyColumns, FramesOfAnOlderDatabaseReadAsTheirMismatchCountsSay) {
    const test::TempDir temp("accuracy", "migrate");
    const fs::path& dir = temp.path();
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
        EXPECT_EQ(count(store.db(), "PRAGMA user_version"), latest_schema_version());
        check(store.db());
    }
}

TEST(AccuracyColumns, ARunsFramesRoundTripThroughTheStoreAndMerge) {
    const test::TempDir temp("accuracy", "roundtrip");
    const fs::path& dir = temp.path();
    const Recording scene = test::with_shapes(test::generated_scene("irregular", 400, 3, 5), 9);
    // The candidate level on shapes: precision below 1, recall 1; the shape level runs the narrow
    // phase (n_ro > 0).
    std::vector<SimulationResult> results;
    for (const char* level : {"candidates", "shapes"})
        results.push_back(simulate(scene, find_structure("ug"), {{"query", level}}));
    ASSERT_GT(results[1].frames.back().counters.n_ro, 0u);
    ASSERT_GT(results[1].frames.back().counters.n_mp, 0u);   // the grid's steps' coherence is stored too
    ASSERT_GT(results[1].frames.back().writes, 0u);          // and its update's cells written
    ASSERT_GT(results[1].frames.back().counters.n_dup, 0u);  // and the box hits its cells dropped
    ASSERT_LT(results[0].frames.back().correct, results[0].frames.back().returned);

    const Experiment e =
        parse_experiment(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "ug"}]})", "roundtrip", ".");
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
                "SELECT frame.frame, returned, correct, relevant, n_ro, n_ro_hits, n_th, n_mp, n_miss, writes, n_dup "
                "FROM "
                "frame "
                "JOIN cell ON "
                "cell.id = frame.cell_id WHERE cell.cell_key LIKE '%' || ? ORDER BY frame.frame");
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
                EXPECT_EQ(std::uint64_t(s.int64(6)), f.counters.n_th) << path;
                EXPECT_EQ(std::uint64_t(s.int64(7)), f.counters.n_mp) << path;
                EXPECT_EQ(std::uint64_t(s.int64(8)), f.counters.n_miss) << path;
                EXPECT_EQ(std::uint64_t(s.int64(9)), f.writes) << path;
                EXPECT_EQ(std::uint64_t(s.int64(10)), f.counters.n_dup) << path;
            }
            EXPECT_EQ(n, results[i].frames.size()) << path;
        }
    }
}

TEST(ParetoFront, KeepsTheFastestConfigurationOfEachAccuracyLevel) {
    const std::vector<TradeoffPoint> points{
        {"dbvh shapes", 0.9, 1.0}, {"ug boxes", 0.6, 0.78}, {"ug candidates", 0.4, 0.31}, {"hg boxes", 0.7, 0.5},
        {"slow exact", 2.0, 1.0},  {"tie", 0.4, 0.2},       {"broken", NAN, 1.0}};
    const std::vector<std::size_t> front = pareto_front(points);
    EXPECT_EQ(front, (std::vector<std::size_t>{2, 1, 0}));
    EXPECT_EQ(front_reading("S", "precision", points, front),
              "On S, the precision front is: ug candidates (0.400 ms, precision 0.31), ug boxes (0.600 ms, 0.78), "
              "dbvh shapes (0.900 ms, 1.00).");
    // The fastest configuration being the most accurate leaves it alone on the front.
    EXPECT_EQ(pareto_front({{"a", 1, 1}, {"b", 2, 0.5}}), (std::vector<std::size_t>{0}));
    EXPECT_TRUE(pareto_front({}).empty());
}

std::string accuracy_error(const std::string& text) {
    return test::input_error_of([&] { parse_accuracy(text); });
}

TEST(AccuracyConstraint, ParsesTheThreeFormsAndNamesWhatIsWrong) {
    EXPECT_EQ(parse_accuracy("exact").kind, AccuracyConstraint::Kind::exact);
    const AccuracyConstraint r = parse_accuracy("recall>=0.9");
    EXPECT_EQ(r.kind, AccuracyConstraint::Kind::recall);
    EXPECT_DOUBLE_EQ(r.bound, 0.9);
    EXPECT_EQ(r.text(), "recall>=0.9");
    EXPECT_EQ(parse_accuracy("precision>=1").text(), "precision>=1");
    EXPECT_EQ(parse_accuracy("precision>=0").bound, 0.0);
    EXPECT_NE(accuracy_error("exactly").find("--accuracy: \"exactly\" is not a constraint"), std::string::npos);
    EXPECT_NE(accuracy_error("speed>=0.5").find("unknown measure \"speed\""), std::string::npos);
    EXPECT_NE(accuracy_error("recall>=nan").find("\"nan\" is not a number"), std::string::npos);
    EXPECT_NE(accuracy_error("recall>=").find("\"\" is not a number"), std::string::npos);
    EXPECT_NE(accuracy_error("recall>=0.5x").find("is not a number"), std::string::npos);
    EXPECT_NE(accuracy_error("precision>=1.5").find("precision 1.5 is outside 0..1"), std::string::npos);
    EXPECT_NE(accuracy_error("recall>=-0.1").find("outside 0..1"), std::string::npos);
}

/// A measured candidate for the selection tests: `ms` per frame at a level with `precision`.
Candidate synthetic(const char* structure, const char* level, double ms, double precision) {
    Candidate c;
    c.structure = structure;
    c.params = {{"query", level}};
    MeasuredCost m{ms, 0, 0, ms, 1e6, {}};
    m.accuracy.verified = true;
    m.accuracy.exact_level = std::string(level) != "candidates";
    m.accuracy.precision = precision;
    c.measured = m;
    return c;
}

TEST(AccuracyConstraint, ExactRejectsAFasterCandidateLevelThatAPrecisionBoundAccepts) {
    const Candidate fast = synthetic("ug", "candidates", 0.4, 0.5), slow = synthetic("ug", "boxes", 0.6, 1.0);
    const std::vector<const Candidate*> all{&fast, &slow};
    const auto exact = meeting(all, parse_accuracy("exact"));
    ASSERT_EQ(exact.size(), 1u);
    EXPECT_EQ(exact[0], &slow);
    const auto loose = meeting(all, parse_accuracy("precision>=0.4"));
    ASSERT_EQ(loose.size(), 2u);
    EXPECT_EQ(loose[simplest_within(loose, 0.03)], &fast);
    EXPECT_EQ(meeting(all, parse_accuracy("precision>=0.6")).size(), 1u);
    // A box-level configuration with mismatches is not exact; an unverified one meets no bound.
    Candidate wrong = synthetic("ug", "boxes", 0.3, 1.0);
    wrong.measured->accuracy.mismatches = 2;
    EXPECT_TRUE(meeting({&wrong}, parse_accuracy("exact")).empty());
    Candidate unverified = synthetic("ug", "boxes", 0.3, 1.0);
    unverified.measured->accuracy.verified = false;
    EXPECT_EQ(meeting({&unverified}, parse_accuracy("exact")).size(), 1u);
    EXPECT_TRUE(meeting({&unverified}, parse_accuracy("recall>=0.5")).empty());

    // advise ranks the same way: fastest first, the recommendation the fastest that meets.
    std::vector<AdviceRow> rows{{"ug", "boxes", *slow.measured, false}, {"ug", "candidates", *fast.measured, false}};
    EXPECT_EQ(rank_advice(rows, parse_accuracy("exact")), std::optional<std::size_t>(1));
    EXPECT_EQ(rows[0].params, "candidates");
    EXPECT_FALSE(rows[0].meets);
    EXPECT_EQ(rank_advice(rows, parse_accuracy("precision>=0.4")), std::optional<std::size_t>(0));
    EXPECT_EQ(rank_advice(rows, parse_accuracy("precision>=1.0")), std::optional<std::size_t>(1));
    rows.pop_back();  // only the candidate level left
    EXPECT_EQ(rank_advice(rows, parse_accuracy("exact")), std::nullopt);
}

TEST(AccuracyConstraint, TuningSearchesTheQueryLevelOnlyWhenInexactAnswersAreAllowed) {
    const std::string text =
        R"({"structures": ["ug"], "mode": "measured", "budget": 6, "frames": 3, "rays_per_frame": 200, "repetitions": 1,
            "space": {"ug": {"density": [1, 4]}},
            "categories": [{"name": "small", "scenes": [{"generator": "irregular", "objects": 1500}]}]})";
    TuneSpec exact = parse_tune_spec(text, "t.json", ".");
    set_accuracy(exact, parse_accuracy("exact"));
    ASSERT_EQ(exact.space.at("ug").size(), 1u);  // density only
    const CategoryTuning e = tune_category(exact, exact.categories[0]);
    for (const Candidate& c : e.structures.at(0).candidates) {
        EXPECT_EQ(query_level_of(c.params), QueryLevel::boxes) << c.params;
        EXPECT_FALSE(c.measured->accuracy.verified);  // exact at the box level needs no verification
    }

    TuneSpec loose = parse_tune_spec(text, "t.json", ".");
    set_accuracy(loose, parse_accuracy("precision>=0"));
    ASSERT_EQ(loose.space.at("ug").size(), 2u);
    EXPECT_EQ(loose.space.at("ug")[1].name, "query");
    const CategoryTuning t = tune_category(loose, loose.categories[0]);
    bool candidates_seen = false;
    for (const Candidate& c : t.structures.at(0).candidates) {
        ASSERT_TRUE(c.measured->accuracy.verified);
        const std::string level = c.params.value("query", "boxes");
        if (level == "candidates") {
            candidates_seen = true;
            // The candidates of a grid cell include boxes the ray misses: precision below 1.
            EXPECT_LT(c.measured->accuracy.precision, 1.0);
            EXPECT_DOUBLE_EQ(c.measured->accuracy.recall, 1.0);
            EXPECT_FALSE(c.measured->accuracy.exact_level);
        } else {
            EXPECT_DOUBLE_EQ(c.measured->accuracy.precision, 1.0);  // a box-only scene
            EXPECT_EQ(c.measured->accuracy.mismatches, 0u);
        }
    }
    EXPECT_TRUE(candidates_seen);
    // Everything meets precision >= 0: the choice is the fastest of all (up to the 3% rule).
    double fastest = INFINITY;
    for (const Candidate& c : t.structures.at(0).candidates) fastest = std::min(fastest, c.measured->ms);
    EXPECT_EQ(t.fastest.measured->ms, fastest);
}

TEST(AccuracyConstraint, OnShapesOnlyTheNarrowPhaseIsPreciseAndABoundNothingMeetsIsOneLine) {
    const test::TempDir temp("accuracy", "shaped");
    const fs::path& dir = temp.path();
    const std::string scene = (dir / "shaped.rcbscene").string();
    write_recording(test::with_shapes(test::generated_scene("irregular", 600, 3, 11), 4), scene);
    const std::string text =
        R"({"structures": ["ug"], "mode": "measured", "budget": 6, "repetitions": 1, "warmup_frames": 0,
            "space": {"ug": {"query": ["candidates", "shapes"]}},
            "categories": [{"name": "shaped", "scenes": [{"recording": ")" +
        scene + R"("}]}]})";
    TuneSpec spec = parse_tune_spec(text, "t.json", ".");
    set_accuracy(spec, parse_accuracy("precision>=1"));
    const CategoryTuning t = tune_category(spec, spec.categories[0]);
    // The box level (the defaults, always measured) reports boxes whose shape the ray misses.
    for (const Candidate& c : t.structures.at(0).candidates) {
        const std::string level = c.params.value("query", "boxes");
        if (level == "shapes")
            EXPECT_DOUBLE_EQ(c.measured->accuracy.precision, 1.0);
        else
            EXPECT_LT(c.measured->accuracy.precision, 1.0) << level;
        EXPECT_DOUBLE_EQ(c.measured->accuracy.recall, 1.0) << level;
    }
    EXPECT_EQ(t.chosen.params.value("query", ""), "shapes");

    // Without the narrow phase in the space nothing meets precision 1: one line naming the
    // category and the constraint.
    spec.space["ug"] = {{"query", {"candidates"}}};
    EXPECT_EQ(test::input_error_of([&] { tune_category(spec, spec.categories[0]); }),
              "tune: no configuration of ug on category shaped meets --accuracy precision>=1");
}

TEST(AccuracyConstraint, TheCommandsRefuseABadConstraintInOneLine) {
    const test::TempDir temp("accuracy", "cli");
    const fs::path& dir = temp.path();
    const std::string scene = (dir / "s.rcbscene").string();
    const auto run = [](const std::string& args) {
        return ::test::run_shell(std::string(RCBENCH_BINARY) + " " + args);
    };
    ASSERT_EQ(run("scene gen --preset uni-s --frames 2 --rays 20 -o " + scene).code, 0);
    for (const char* bad : {"recall>=nan", "precision>=2", "fast"}) {
        const ::test::Outcome r = run("advise " + scene + " --accuracy '" + bad + "'");
        EXPECT_EQ(r.code, 2) << r.err;
        EXPECT_EQ(r.err.rfind("rcbench: --accuracy: ", 0), 0u) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
    const ::test::Outcome tune = run("tune " + scene + " --accuracy 'recall>=1.5'");
    EXPECT_EQ(tune.code, 2) << tune.err;
    EXPECT_EQ(tune.err.rfind("rcbench: --accuracy: recall 1.5 is outside 0..1", 0), 0u) << tune.err;
}

}  // namespace
}  // namespace rcb

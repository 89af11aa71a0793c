// The experiment runner: validation, plans, the SQLite store, resume after kill -9, concurrent
// writers, merge, and compare on synthetic data with and without a real shift.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/base/error.h"
#include "core/base/number_text.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "core/scene/recording_io.h"
#include "analysis/cost_model.h"
#include "runner/compare.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/store.h"
#include "tuner/tuning.h"
#include "tests/test_scenes.h"

extern char** environ;

namespace rcb {
namespace {

namespace fs = std::filesystem;

std::string error_of(const std::string& text) {
    return test::input_error_of([&] { parse_experiment(text, "exp.json", "."); });
}

const char* kMinimal = R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})";

TEST(Experiment, ValidationNamesTheJsonPath) {
    EXPECT_EQ(error_of(kMinimal), "");
    EXPECT_EQ(error_of("{"), error_of("{"));  // stable
    EXPECT_EQ(error_of("{").find("exp.json: not valid JSON"), 0u);
    EXPECT_EQ(
        error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "frame": 3})"),
        "exp.json: frame: unknown key (known: cache, description, frames, max_repetitions, name, ray_mix, "
        "rays_per_frame, repeat_interval, repetitions, scenes, seeds, structures, threads, verify, warmup_frames)");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "cache": "hot"})"),
              "exp.json: cache: expected \"warm\" or \"cold\", got \"hot\"");
    // The range criterion's old key is refused by name, pointing to the new one.
    EXPECT_EQ(
        error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "repeat_spread": 0.05})"),
        "exp.json: repeat_spread: replaced by repeat_interval (the 95% interval's half-width over repetitions as a "
        "fraction of the median; experiments/README.md)");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "repeat_interval": -1})"),
              "exp.json: repeat_interval: expected a number in 0..10, got -1");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "frames": "ten"})"),
              "exp.json: frames: expected an integer in 1..1000000, got \"ten\"");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}, {"preset": "uni-q"}], "structures": [{"name": "bf"}]})")
                  .find("exp.json: scenes[1].preset: unknown preset 'uni-q' (known: uni-s, uni-m, uni-l, irreg-s, "
                        "irreg-m, irreg-l, irreg-xl"),
              0u);
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}, {"name": "kd"}]})")
                  .find("exp.json: structures[1].name: unknown structure 'kd' (known: bf"),
              0u);
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf", "params": {"depth": 3}}]})"),
              "exp.json: structures[0].params.depth: unknown parameter of bf (known: cast_threads, query, leaf_bv)");
    // A structure's threads beyond the run's would be measured on the run's (TBB's cap is global).
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}],
                           "structures": [{"name": "wbvh", "grids": [{"cast_threads": [1, 2]}]}]})"),
              "exp.json: structures[0].grids[0].cast_threads: 2 threads, more than the experiment's \"threads\" (1), "
              "which caps every thread of the run: set \"threads\" to at least 2");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "threads": 2,
                           "structures": [{"name": "wbvh", "grids": [{"cast_threads": [1, 2]}]}]})"),
              "");
    EXPECT_EQ(error_of(R"({"scenes": [{"recording": "missing.rcbscene"}], "structures": [{"name": "bf"}]})"),
              "exp.json: scenes[0].recording: file not found: missing.rcbscene");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "generator": "uniform"}], "structures": [{"name": "bf"}]})"),
              "exp.json: scenes[0]: give exactly one of \"preset\", \"generator\", \"recording\" or \"import\"");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "ray_mix": "up"}], "structures": [{"name": "bf"}]})")
                  .find("exp.json: scenes[0].ray_mix: ray mix 'up': unknown mode 'up'"),
              0u);
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "objects": [10, -1]}], "structures": [{"name": "bf"}]})"),
              "exp.json: scenes[0].objects[1]: expected an integer in 1..100000000, got -1");
    EXPECT_EQ(error_of(R"({"scenes": [], "structures": [{"name": "bf"}]})"),
              "exp.json: scenes: expected a non-empty list of scenes");
    // Every generator is accepted, the failure modes included.
    EXPECT_EQ(
        error_of(R"({"scenes": [{"generator": "same-centroid", "objects": 50}], "structures": [{"name": "bf"}]})"), "");
    EXPECT_EQ(
        error_of(R"({"scenes": [{"generator": "cubes", "objects": 50}], "structures": [{"name": "bf"}]})"),
        "exp.json: scenes[0].generator: expected one of uniform, irregular, jittered, clusters, stadium, identical, "
        "same-centroid, flat, "
        "slivers, outlier, nested, pile, collapse, explosion, brownian, freefall, gravity, got \"cubes\"");
    EXPECT_EQ(
        error_of(
            R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "frames": 3, "warmup_frames": 3})"),
        "exp.json: warmup_frames: leaves no measured frame in scene uni-s");
}

TEST(Experiment, TheCacheIsWarmUnlessTheFileAsksForCold) {
    EXPECT_FALSE(parse_experiment(kMinimal, "exp.json", ".").cold_cache);
    EXPECT_TRUE(
        parse_experiment(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "cache": "cold"})",
                         "exp.json", ".")
            .cold_cache);
}

TEST(Experiment, OversizedOrMalformedRangesAndPlansAreRefusedBeforeAllocation) {
    auto with_structure = [](const std::string& structure, const std::string& extra = "") {
        return R"({"scenes": [{"preset": "uni-s"}], )" + extra + R"("structures": [)" + structure + "]}";
    };
    // A factor barely above 1: billions of steps to reach "to" (this hung).
    EXPECT_EQ(error_of(with_structure(
                  R"({"name": "hg", "grids": [{"max_capacity": {"from": 1, "to": 8, "times": 1.000000000000001}}]})")),
              "exp.json: structures[0].grids[0].max_capacity: the range takes more than 10000 steps");
    EXPECT_EQ(
        error_of(with_structure(R"({"name": "ug", "grids": [{"density": {"from": 0.1, "to": 64, "step": 1e-9}}]})")),
        "exp.json: structures[0].grids[0].density: the range takes more than 10000 steps");
    // A range over a boolean or a choice: a clear error with its path (was a bare library type error).
    EXPECT_EQ(error_of(with_structure(
                  R"({"name": "ug", "grids": [{"outlier_guard": {"from": true, "to": true, "step": 1}}]})")),
              "exp.json: structures[0].grids[0].outlier_guard: a range needs a numeric parameter; give outlier_guard a "
              "value or a "
              "list of values");
    // 1000 repetitions of a 6301-value grid: refused at once instead of expanding 6.3 M cells.
    EXPECT_EQ(error_of(with_structure(R"({"name": "ug", "grids": [{"density": {"from": 1, "to": 64, "step": 0.01}}]})",
                                      R"("repetitions": 1000, )"))
                  .rfind("exp.json: (top level): the plan has 6301000 cells", 0),
              0u);
    EXPECT_EQ(error_of(with_structure(R"({"name": "hg", "grids": [{"amp": {"from": 0.01, "to": 16, "step": 0.002},
                                                                     "max_capacity": {"from": 1, "to": 256, "step": 1}}]})"))
                  .rfind("exp.json: structures[0].grids[0]: the grid has more than 100000 combinations", 0),
              0u);
    // A 5 MB string where a number belongs: the message quotes an excerpt, not the value.
    const std::string message =
        error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}], "frames": ")" +
                 std::string(5'000'000, 'x') + "\"}");
    EXPECT_EQ(message.rfind("exp.json: frames: expected an integer in 1..1000000, got \"xxx", 0), 0u)
        << message.substr(0, 200);
    EXPECT_LT(message.size(), 200u);
}

TEST(NumberText, DecimalRoundedDropsFloatNoiseAndKeepsTwelveDigits) {
    EXPECT_EQ(decimal_rounded(4.000000000000001), 4.0);
    EXPECT_EQ(decimal_rounded(0.1 + 2 * 0.1), 0.3);
    EXPECT_EQ(decimal_rounded(-(0.1 + 2 * 0.1)), -0.3);
    EXPECT_EQ(decimal_rounded(0.1767766952966369), 0.176776695297);
    EXPECT_EQ(decimal_rounded(1.23456789012345, 3), 1.23);
    EXPECT_EQ(decimal_rounded(0.0), 0.0);
    EXPECT_EQ(decimal_rounded(1e300 * 1.0000000000000002), 1e300);
    EXPECT_EQ(decimal_rounded(INFINITY), INFINITY);
    EXPECT_TRUE(std::isnan(decimal_rounded(NAN)));
}

TEST(Experiment, RangeLevelsAreTheDecimalsTheyStandFor) {
    // 0.125 × √2 ten times by a running product was 4.000000000000001 beside ug's default 4.0: a
    // second configuration and a second cell key for one structure in effect.
    const Experiment g = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}],
            "structures": [{"name": "ug", "params": {"density": {"from": 0.125, "to": 64, "times": 1.4142135623730951}}}]})",
        "g", ".");
    ASSERT_EQ(g.configs.size(), 19u);
    const nlohmann::json default_density = find_structure("ug").defaults()["density"];
    std::size_t at_default = 0;
    for (std::size_t k = 0; k < g.configs.size(); ++k) {
        const nlohmann::json& level = g.configs[k].params["density"];
        EXPECT_EQ(level.get<double>(), decimal_rounded(level.get<double>())) << level.dump();
        EXPECT_LE(level.dump().size(), 14u) << level.dump();  // "0.176776695297": 12 digits, no noise
        if (k % 2 == 0) {
            EXPECT_EQ(level.get<double>(), 0.125 * double(1 << (k / 2))) << k;  // powers of two
        }
        at_default += level == default_density;
    }
    EXPECT_EQ(at_default, 1u);
    EXPECT_EQ(g.configs[10].params["density"].dump(), "4.0");
    // The range's level at the default is the file's that names the default: the same cell.
    const Experiment d = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "ug", "params": {"density": 4.0}}]})", "d", ".");
    EXPECT_EQ(cell_key(g, 0, 10, 0), cell_key(d, 0, 0, 0));
    // Arithmetic ranges: 0.1 + 2 × 0.1 is 0.3, not 0.30000000000000004.
    const Experiment a = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}],
            "structures": [{"name": "dbvh", "params": {"margin": {"from": 0.1, "to": 0.5, "step": 0.1}}}]})",
        "a", ".");
    std::vector<std::string> margins;
    for (const auto& c : a.configs) margins.push_back(c.params["margin"].dump());
    EXPECT_EQ(margins, (std::vector<std::string>{"0.1", "0.2", "0.3", "0.4", "0.5"}));
    // A first level of more digits than the rounding keeps stays as given (within the range).
    const Experiment f = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}],
            "structures": [{"name": "ug", "params": {"density": {"from": 0.1234567890123456, "to": 1, "times": 2}}}]})",
        "f", ".");
    ASSERT_EQ(f.configs.size(), 4u);
    EXPECT_EQ(f.configs[0].params["density"].get<double>(), 0.1234567890123456);
    EXPECT_EQ(f.configs[1].params["density"].get<double>(), 0.246913578025);
}

TEST(Experiment, PlanRunsRepetitionROfEveryCellBeforeRepetitionROnePlusOne) {
    const Experiment e = parse_experiment(
        R"({"repetitions": 2, "seeds": [1, 2], "scenes": [{"preset": "uni-s"}, {"generator": "irregular", "objects": [100, 200]}],
            "structures": [{"name": "bf"}]})",
        "e", ".");
    ASSERT_EQ(e.scenes.size(), 6u);  // uni-s × 2 seeds, irregular × 2 sizes × 2 seeds
    EXPECT_EQ(e.scenes[0].name, "uni-s-s1");
    EXPECT_EQ(e.scenes[2].name, "irregular-100-s1");
    EXPECT_EQ(e.plan.size(), 12u);
    // The next cell is another scene's repetition 0, not this scene's repetition 1.
    for (std::size_t i = 0; i < e.plan.size(); ++i) EXPECT_EQ(e.plan[i].repetition, i / 6) << i;
    std::set<std::size_t> first_round;
    for (std::size_t i = 0; i < 6; ++i) first_round.insert(e.plan[i].scene);
    EXPECT_EQ(first_round.size(), 6u);
    std::set<std::string> keys;
    for (const Cell& c : e.plan) keys.insert(c.key);
    EXPECT_EQ(keys.size(), e.plan.size());  // every cell has its own key
    // Keys depend on content, not on position: the same cell in another file has the same key.
    const Experiment f = parse_experiment(R"({"repetitions": 2, "seeds": [1, 2], "scenes": [{"preset": "uni-s"}],
                                              "structures": [{"name": "bf"}]})",
                                          "f", ".");
    EXPECT_EQ(cell_key(f, 0, 0, 1), cell_key(e, 0, 0, 1));
    const auto key_of = [](const Experiment& x, std::size_t scene, std::uint32_t repetition) {
        for (const Cell& c : x.plan)
            if (c.scene == scene && c.repetition == repetition) return c.key;
        return std::string();
    };
    EXPECT_EQ(key_of(f, 0, 1), key_of(e, 0, 1));
    EXPECT_FALSE(key_of(e, 0, 1).empty());
}

TEST(Experiment, ValueListsAndRangesExpandIntoTheCrossProduct) {
    const Experiment e = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}],
            "structures": [{"name": "dbvh", "params": {"margin": {"from": 0, "to": 0.3, "step": 0.1},
                                                       "bins": {"from": 4, "to": 16, "times": 2}, "mode": "rebuild"}},
                           {"name": "dbvh", "grids": [{"margin": 0.2, "bins": 8, "mode": "rebuild"}, {"rotate": [true, false]}]}]})",
        "e", ".");
    // 4 margins × 3 bin counts, then the second entry: one duplicate of the first grid and two rotate values.
    ASSERT_EQ(e.configs.size(), 12u + 2u);
    std::set<std::pair<long, long>> grid;  // (margin × 10, bins) of the first entry
    for (std::size_t i = 0; i < 12; ++i) {
        EXPECT_EQ(e.configs[i].params["mode"], "rebuild");
        EXPECT_EQ(e.configs[i].params["rotate"], true);  // defaults completed
        grid.insert(
            {std::lround(e.configs[i].params["margin"].get<double>() * 10), e.configs[i].params["bins"].get<long>()});
    }
    std::set<std::pair<long, long>> want;
    for (long m : {0, 1, 2, 3})  // the end of a float range is kept despite rounding
        for (long b : {4, 8, 16}) want.insert({m, b});
    EXPECT_EQ(grid, want);
    EXPECT_EQ(e.configs[12].params["rotate"], true);
    EXPECT_EQ(e.configs[13].params["rotate"], false);
    // A range whose last level lands a rounding past its end, at the parameter's maximum: the end
    // itself (0.125 × √2^18 was 64.00000000000001, refused as beyond ug's density range).
    const Experiment g = parse_experiment(
        R"({"scenes": [{"preset": "uni-s"}],
            "structures": [{"name": "ug", "params": {"density": {"from": 0.125, "to": 64, "times": 1.4142135623730951}}}]})",
        "g", ".");
    ASSERT_EQ(g.configs.size(), 19u);
    EXPECT_EQ(g.configs.back().params["density"].get<double>(), 64.0);
    EXPECT_EQ(
        error_of(
            R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "dbvh", "params": {"bins": {"from": 4, "to": 8, "step": 1.5}}}]})"),
        "exp.json: structures[0].params.bins.step: expected a positive integer, got 1.5");
    EXPECT_EQ(
        error_of(
            R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "dbvh", "params": {"bins": [4, 300]}}]})"),
        "exp.json: structures[0].params.bins[1]: expected an integer in 2..256, got 300");
    EXPECT_EQ(
        error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "dbvh", "params": {"mode": "x"}}]})"),
        "exp.json: structures[0].params.mode: expected one of incremental, rebuild, got \"x\"");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf", "grids": []}]})"),
              "exp.json: structures[0].grids: expected a non-empty list of parameter grids");
}

TEST(Experiment, EveryShippedExperimentAndTuningFileIsValid) {
    std::size_t experiments = 0, tunings = 0;
    for (const auto& entry : fs::directory_iterator(fs::path(RCBENCH_SOURCE_DIR) / "experiments")) {
        if (entry.path().extension() != ".json") continue;
        const std::string file = entry.path().filename().string();
        const bool tuning = file.rfind("tune-", 0) == 0;  // tuning files (rcbench tune)
        ++(tuning ? tunings : experiments);
        const std::string message = test::input_error_of([&] {
            if (tuning)
                EXPECT_FALSE(load_tune_spec(entry.path().string()).categories.empty()) << file;
            else
                EXPECT_FALSE(load_experiment(entry.path().string()).plan.empty()) << file;
        });
        if (!message.empty()) {
            // Real maps and models are fetched on demand into data/<set>/ (scripts/fetch_maps.sh
            // with or without a set's argument), never committed: the only acceptable error is a
            // missing file of a set that has not been fetched.
            const std::size_t at = message.find("/data/");
            bool missing_data = false;
            if (message.find("file not found") != std::string::npos && at != std::string::npos) {
                const std::size_t from = at + 6, to = message.find('/', from);
                const std::string set = message.substr(from, to == std::string::npos ? 0 : to - from);
                missing_data = !set.empty() && !fs::exists(fs::path(RCBENCH_SOURCE_DIR) / "data" / set);
            }
            EXPECT_TRUE(missing_data) << message;
        }
    }
    EXPECT_GE(experiments, 4u);  // quick, thesis, dense, scale, …
    EXPECT_GE(tunings, 3u);      // tune-grids, tune-validate, tune-advise
}

/// A fabricated result whose frames take `base × factor` ns with multiplicative noise.
SimulationResult synthetic_result(double base, double factor, std::uint64_t seed, int frames) {
    SimulationResult r;
    r.structure = "bf";
    r.params = nlohmann::json::object();
    r.objects = 100;
    Random rng(seed);
    for (int f = 0; f < frames; ++f) {
        FrameResult fr;
        fr.frame = std::uint32_t(f + 1);
        fr.rays = 1000;
        fr.raycast_ns = std::uint64_t(base * factor * (1 + 0.03 * rng.normal()));
        fr.update_ns = std::uint64_t(1000 * (1 + 0.03 * rng.normal()));
        fr.stats = nlohmann::json::object();
        r.frames.push_back(fr);
    }
    return r;
}

TEST(Store, CompareTellsATenPercentSlowdownFromNoise) {
    const test::TempDir temp("runner", "compare");
    const fs::path& dir = temp.path();
    const std::string db_path = (dir / "r.db").string();
    const Experiment e = parse_experiment(kMinimal, "synthetic", ".");
    const Recording scene = load_scene(e.scenes[0]);
    const std::string hash = recording_hash(scene);
    {
        ResultStore store(db_path);
        const std::int64_t ex = store.experiment_id(e);
        const double factors[] = {1.0, 1.1, 1.0};  // baseline, a real 10% slowdown, noise only
        for (int run = 0; run < 3; ++run) {
            const std::int64_t id = store.begin_run(ex, RunInfo::current(1, "", e));
            for (std::uint32_t rep = 0; rep < 3; ++rep) {
                Cell c = e.plan[0];
                c.repetition = rep;
                c.key += std::to_string(rep);
                ASSERT_TRUE(store.store_cell(id, ex, c, e.scenes[0], scene, hash,
                                             synthetic_result(1e6, factors[run], 100 * run + rep, 20)));
            }
        }
    }
    auto db = open_read_only(db_path);
    const auto slow = compare_runs(*db, "1", "2", "raycast", 0.05);
    ASSERT_EQ(slow.size(), 1u);
    EXPECT_EQ(slow[0].verdict, "slower");
    EXPECT_NEAR(slow[0].ratio, 1.1, 0.02);
    EXPECT_LT(slow[0].p_value, 1e-6);
    const auto same = compare_runs(*db, "1", "3", "raycast", 0.05);
    EXPECT_EQ(same[0].verdict, "same");
    EXPECT_NEAR(same[0].ratio, 1.0, 0.02);
    EXPECT_THROW(compare_runs(*db, "1", "99", "raycast", 0.05), InputError);
}

TEST(Store, MannWhitneyMatchesTextbookValues) {
    // Identical samples: no evidence of a difference.
    EXPECT_NEAR(mann_whitney_p({1, 2, 3, 4, 5}, {1, 2, 3, 4, 5}), 1.0, 1e-9);
    // Complete separation of 10 vs 10: U = 0, z = (50 - 0.5)/13.23, p ≈ 0.00018.
    std::vector<double> a, b;
    for (int i = 0; i < 10; ++i) a.push_back(i), b.push_back(100 + i);
    EXPECT_NEAR(mann_whitney_p(a, b), 0.000183, 0.00002);
}

TEST(Store, ReadersSeeAnOlderDatabaseAtTheLatestSchemaWithoutChangingTheFile) {
    const test::TempDir temp("runner", "old_reader");
    const fs::path& dir = temp.path();
    const std::string v3 = (dir / "v3.db").string();
    {
        ResultStore old(v3, 3);  // before the machine state, scene features and calibration tables
        old.db().exec("INSERT INTO experiment(name) VALUES ('kept')");
    }
    const auto version_of = [](Database& db) {
        Statement v = db.prepare("PRAGMA user_version");
        v.step();
        return v.int64(0);
    };
    {
        auto db = open_read_only(v3);
        EXPECT_EQ(version_of(*db), latest_schema_version());
        Statement s = db->prepare(
            "SELECT (SELECT count(*) FROM experiment WHERE name = 'kept'), (SELECT count(*) FROM calibration), "
            "(SELECT count(*) FROM cell_state), (SELECT count(*) FROM scene_feature)");
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 1);
        EXPECT_EQ(s.int64(1) + s.int64(2) + s.int64(3), 0);
    }
    Database file(v3, true);
    EXPECT_EQ(version_of(file), 3);  // the file itself was not migrated
}

TEST(Store, RefusesANewerSchemaAndMigratesAnOlderOne) {
    const test::TempDir temp("runner", "schema");
    const fs::path& dir = temp.path();
    const std::string old_db = (dir / "old.db").string();
    { ResultStore empty(old_db, 0); }  // a database at version 0: no tables yet
    {
        ResultStore store(old_db);  // migrated on open
        Statement s = store.db().prepare("SELECT count(*) FROM sqlite_master WHERE name IN ('run', 'cell', 'frame')");
        s.step();
        EXPECT_EQ(s.int64(0), 3);
    }
    // A version-1 database with data keeps it and gains the version-2 tables (the cost-model fits).
    const std::string v1_db = (dir / "v1.db").string();
    {
        ResultStore v1(v1_db, 1);
        v1.db().exec("INSERT INTO experiment(name) VALUES ('kept')");
        Statement s = v1.db().prepare("SELECT count(*) FROM sqlite_master WHERE name = 'fit'");
        s.step();
        EXPECT_EQ(s.int64(0), 0);
    }
    {
        ResultStore migrated(v1_db);
        Statement s = migrated.db().prepare(
            "SELECT (SELECT count(*) FROM experiment WHERE name = 'kept'), "
            "(SELECT count(*) FROM sqlite_master WHERE name IN ('fit', 'fit_coefficient'))");
        s.step();
        EXPECT_EQ(s.int64(0), 1);
        EXPECT_EQ(s.int64(1), 2);
        Statement v = migrated.db().prepare("PRAGMA user_version");
        v.step();
        EXPECT_EQ(v.int64(0), latest_schema_version());
    }
    const std::string new_db = (dir / "new.db").string();
    {
        Database db(new_db, false);
        db.exec("PRAGMA user_version = 99");
    }
    test::expect_input_error([&] { ResultStore store(new_db); }, "schema version 99 is newer than this rcbench writes");
    EXPECT_THROW(open_read_only((dir / "missing.db").string()), InputError);
}

/// Spawns `program` with `args`, its output appended to `log`; the pid, or 0 when it could not start.
pid_t spawn_logged(const std::string& program, const std::vector<std::string>& args, const std::string& log) {
    std::vector<std::string> all{program};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    pid_t pid = 0;
    if (posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid = 0;
    posix_spawn_file_actions_destroy(&actions);
    return pid;
}

/// Runs the rcbench binary; returns its pid.
pid_t spawn_rcbench(const std::vector<std::string>& args, const std::string& log) {
    const pid_t pid = spawn_logged(RCBENCH_BINARY, args, log);
    EXPECT_NE(pid, 0);
    return pid;
}

int wait_exit(pid_t pid) {
    int status = 0;
    waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Runs `experiment` into `db` (shard `shard`, empty: the whole plan) until `cells` cells are
/// stored, then kills the runner with SIGKILL (tests/killed_run.cpp): a run killed at a known
/// point, whatever the machine's speed. Returns true when it died by SIGKILL.
bool run_killed_after(const fs::path& experiment, const std::string& db, int cells, const std::string& shard,
                      const std::string& log) {
    std::vector<std::string> args{experiment.string(), db, std::to_string(cells)};
    if (!shard.empty()) args.push_back(shard);
    const pid_t pid = spawn_logged(RCB_KILLED_RUN_BINARY, args, log);
    if (pid == 0) return false;
    int status = 0;
    waitpid(pid, &status, 0);
    return WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
}

std::int64_t count(const std::string& db_path, const std::string& sql) {
    if (!fs::exists(db_path)) return 0;
    try {
        Database db(db_path, true);
        Statement s = db.prepare(sql);
        return s.step() ? s.int64(0) : 0;
    } catch (const SqlError&) {
        return 0;  // not created yet
    }
}

void write_experiment(const fs::path& path, int repetitions) {
    std::ofstream(path)
        << R"({"name": "resume", "frames": 4, "rays_per_frame": 300, "repetitions": )" << repetitions
        << R"(, "scenes": [{"generator": "irregular", "objects": 4000}, {"generator": "uniform", "objects": 3000}],
                             "structures": [{"name": "bf"}]})";
}

TEST(Store, KilledRunResumesToTheSameRowsAsAnUninterruptedRun) {
    const test::TempDir temp("runner", "resume");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 8);  // 16 cells
    const std::string killed = (dir / "killed.db").string(), whole = (dir / "whole.db").string();
    const std::string log = (dir / "log.txt").string();

    ASSERT_TRUE(run_killed_after(exp, killed, 3, "", log)) << "the run was not killed";
    EXPECT_EQ(count(killed, "SELECT count(*) FROM cell"), 3);
    EXPECT_EQ(count(killed, "SELECT count(*) FROM run WHERE finished_at IS NULL"), 1);

    ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--db", killed}, log)), 0);
    ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--db", whole}, log)), 0);
    for (const std::string& db : {killed, whole}) {
        EXPECT_EQ(count(db, "SELECT count(*) FROM run"), 1) << db;
        EXPECT_EQ(count(db, "SELECT count(*) FROM run WHERE finished_at IS NOT NULL"), 1) << db;
        EXPECT_EQ(count(db, "SELECT count(*) FROM cell"), 16) << db;
        EXPECT_EQ(count(db, "SELECT count(DISTINCT cell_key) FROM cell"), 16) << db;
        EXPECT_EQ(count(db, "SELECT count(*) FROM frame"), 16 * 4) << db;
        EXPECT_EQ(count(db, "SELECT sum(hits) FROM frame"), count(whole, "SELECT sum(hits) FROM frame")) << db;
        EXPECT_EQ(count(db, "SELECT sum(n_rb) FROM frame"), count(whole, "SELECT sum(n_rb) FROM frame")) << db;
    }
}

TEST(Store, TwoRunnersOnOneDatabaseBothFinishWithNothingLostOrDuplicated) {
    const test::TempDir temp("runner", "concurrent");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 3);  // 6 cells
    const std::string db = (dir / "shared.db").string(), log = (dir / "log.txt").string();
    const pid_t a = spawn_rcbench({"run", exp.string(), "--db", db}, log);
    const pid_t b = spawn_rcbench({"run", exp.string(), "--db", db}, log);
    EXPECT_EQ(wait_exit(a), 0);
    EXPECT_EQ(wait_exit(b), 0);
    // They share one run (choosing it is one transaction); it is complete and has each cell once.
    const std::int64_t runs = count(db, "SELECT count(*) FROM run");
    EXPECT_EQ(runs, 1);
    EXPECT_EQ(count(db, "SELECT count(*) FROM run WHERE finished_at IS NULL"), 0);
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell"), 6 * runs);
    EXPECT_EQ(count(db, "SELECT count(*) FROM (SELECT DISTINCT run_id, cell_key FROM cell)"), 6 * runs);
    EXPECT_EQ(count(db, "SELECT count(*) FROM frame"), 6 * runs * 4);
}

TEST(Store, FourRunnersStartedTogetherOnANewDatabaseMakeOneRun) {
    const test::TempDir temp("runner", "four");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 2);  // 4 cells
    const std::string db = (dir / "new.db").string(), log = (dir / "log.txt").string();
    std::vector<pid_t> runners;
    for (int i = 0; i < 4; ++i) runners.push_back(spawn_rcbench({"run", exp.string(), "--db", db}, log));
    for (pid_t p : runners) EXPECT_EQ(wait_exit(p), 0);
    EXPECT_EQ(count(db, "SELECT count(*) FROM run"), 1);
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell"), 4);
    EXPECT_EQ(count(db, "SELECT count(*) FROM run WHERE finished_at IS NULL"), 0);
}

TEST(Store, MergingAKilledShardThenItsResumedRunCompletesTheMergedRun) {
    const test::TempDir temp("runner", "merge_resumed");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 8);  // 16 cells
    const std::string shard = (dir / "shard.db").string(), out = (dir / "all.db").string(),
                      log = (dir / "log.txt").string();
    ASSERT_TRUE(run_killed_after(exp, shard, 3, "1/1", log)) << "the run was not killed";
    ASSERT_EQ(count(shard, "SELECT count(*) FROM cell"), 3);
    ASSERT_EQ(wait_exit(spawn_rcbench({"merge", out, shard}, log)), 0);
    EXPECT_EQ(count(out, "SELECT count(*) FROM run WHERE finished_at IS NULL"), 1);
    ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--shard", "1/1", "--db", shard}, log)), 0);
    ASSERT_EQ(wait_exit(spawn_rcbench({"merge", out, shard}, log)), 0);
    EXPECT_EQ(count(out, "SELECT count(*) FROM run"), 1);
    EXPECT_EQ(count(out, "SELECT count(*) FROM run WHERE finished_at IS NULL"), 0);
    EXPECT_EQ(count(out, "SELECT count(*) FROM cell"), 16);
    EXPECT_EQ(count(out, "SELECT count(DISTINCT cell_key) FROM cell"), 16);
    EXPECT_EQ(count(out, "SELECT count(*) FROM frame"), 16 * 4);
}

TEST(Store, TheAnalysisOfAShardSeesEveryShardOfItsPlan) {
    const test::TempDir temp("runner", "shard_group");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 2);  // 4 cells of 4 frames
    const std::string db = (dir / "all.db").string(), whole = (dir / "whole.db").string(),
                      log = (dir / "log.txt").string();
    for (const char* shard : {"1/2", "2/2"})
        ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--shard", shard, "--db", db}, log)), 0);
    ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--db", whole}, log)), 0);
    Database shards(db, true), single(whole, true);
    const std::int64_t newest = resolve_run(shards, 0, "");
    EXPECT_EQ(load_observations(shards, newest, OverRepetitions::median).size(), 4u * 4u);
    // Each frame once at its fastest, though the two repetitions of a scene ran in two shards.
    EXPECT_EQ(load_observations(shards, newest).size(), 2u * 4u);
    EXPECT_EQ(load_observations(shards, newest).size(), load_observations(single, resolve_run(single, 0, "")).size());
}

TEST(Store, ShardsMergeIntoTheWholePlanAndMergingTwiceAddsNothing) {
    const test::TempDir temp("runner", "shards");
    const fs::path& dir = temp.path();
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 2);  // 4 cells
    const std::string log = (dir / "log.txt").string();
    for (int k = 1; k <= 3; ++k)
        ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--shard", std::to_string(k) + "/3", "--db",
                                           (dir / ("s" + std::to_string(k) + ".db")).string()},
                                          log)),
                  0);
    const std::string out = (dir / "all.db").string();
    std::vector<std::string> merge{"merge", out};
    for (int k = 1; k <= 3; ++k) merge.push_back((dir / ("s" + std::to_string(k) + ".db")).string());
    ASSERT_EQ(wait_exit(spawn_rcbench(merge, log)), 0);
    ASSERT_EQ(wait_exit(spawn_rcbench(merge, log)), 0);  // idempotent
    EXPECT_EQ(count(out, "SELECT count(*) FROM run"), 3);
    EXPECT_EQ(count(out, "SELECT count(*) FROM cell"), 4);
    EXPECT_EQ(count(out, "SELECT count(DISTINCT cell_key) FROM cell"), 4);
    EXPECT_EQ(count(out, "SELECT count(*) FROM frame"), 4 * 4);
}

TEST(Experiment, EveryExpandedThreadCountIsHeldToTheRunsThreads) {
    // A range or a geometric range gives signed values: they got past the cap that a list met.
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}],
                           "structures": [{"name": "wbvh", "grids": [{"cast_threads": {"from": 1, "to": 8, "step": 1}}]}]})"),
              "exp.json: structures[0].grids[0].cast_threads: 2 threads, more than the experiment's \"threads\" (1), "
              "which caps every thread of the run: set \"threads\" to at least 2");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "threads": 4,
                           "structures": [{"name": "lbvh", "grids": [{"threads": {"from": 1, "to": 64, "times": 2}}]}]})"),
              "exp.json: structures[0].grids[0].threads: 8 threads, more than the experiment's \"threads\" (4), "
              "which caps every thread of the run: set \"threads\" to at least 8");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s"}], "threads": 64,
                           "structures": [{"name": "lbvh", "grids": [{"threads": {"from": 1, "to": 64, "times": 2}}]}]})"),
              "");
    EXPECT_EQ(
        error_of(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "lbvh", "params": {"threads": 64}}]})"),
        "exp.json: structures[0].params.threads: 64 threads, more than the experiment's \"threads\" (1), "
        "which caps every thread of the run: set \"threads\" to at least 64");
}

TEST(Experiment, TwoEntriesOfOneSceneAreRefusedNamingBoth) {
    // Same content, two names: one key for both, so the second name's cells were the first's.
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "name": "a"}, {"preset": "uni-s", "name": "b"}],
                           "structures": [{"name": "bf"}]})"),
              "exp.json: scenes[1]: the same scene as scenes[0] (\"a\" and \"b\"): their cells would be stored as "
              "one; make them differ or drop one");
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "seeds": [3, 3]}], "structures": [{"name": "bf"}]})"),
              "exp.json: scenes[0]: gives the scene \"uni-s-s3\" twice (a value repeated in \"objects\" or \"seeds\")");
    // Different content under two names stays two scenes; so do two seeds of one entry.
    EXPECT_EQ(error_of(R"({"scenes": [{"preset": "uni-s", "name": "a"}, {"preset": "uni-s", "name": "b", "seed": 2}],
                           "structures": [{"name": "bf"}]})"),
              "");
    const fs::path dir = test::temp_dir("runner", "same_recording");
    const std::string rec = (dir / "r.rcbscene").string();
    write_recording(test::generated_scene("uniform", 50, 2, 1), rec);
    try {
        parse_experiment(
            R"({"scenes": [{"recording": "r.rcbscene", "name": "x"}, {"recording": "./r.rcbscene", "name": "y"}],
                            "structures": [{"name": "bf"}]})",
            "exp.json", dir.string());
        ADD_FAILURE() << "accepted one recording under two names";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("exp.json: scenes[1]: the same scene as scenes[0] (\"x\" and \"y\")", 0),
                  0u)
            << e.what();
    }
    fs::remove_all(dir);
}

TEST(TuneSpec, TheDefaultSpaceOfEveryStructureFitsTheLimit) {
    // No "structures" (every tunable structure) and ["wbvh"] without a space: the file names no
    // space, so none may be refused as too large; the registry's levels are thinned to fit.
    for (const char* structures : {"", R"("structures": ["wbvh"], )"}) {
        const TuneSpec spec = parse_tune_spec(
            std::string("{") + structures + R"("categories": [{"name": "c", "scenes": [{"preset": "uni-s"}]}]})",
            "t.json", ".");
        EXPECT_FALSE(spec.space.empty());
        for (const auto& [structure, dims] : spec.space) {
            double size = 1;
            for (const SearchDimension& d : dims) size *= double(d.levels.size());
            EXPECT_LE(size, double(kMaxPlanCells)) << structure;
            // Thinning keeps a parameter's default level (where the search starts) when the
            // registry's levels hold it, and the first and last levels.
            const nlohmann::json defaults = find_structure(structure).defaults();
            const std::vector<SearchDimension> registry = default_space(structure);
            for (std::size_t i = 0; i < dims.size(); ++i) {
                const std::vector<nlohmann::json>& all = registry[i].levels;
                EXPECT_EQ(dims[i].levels.front(), all.front()) << structure << "." << dims[i].name;
                EXPECT_EQ(dims[i].levels.back(), all.back()) << structure << "." << dims[i].name;
                if (std::find(all.begin(), all.end(), defaults[dims[i].name]) == all.end()) continue;
                EXPECT_NE(std::find(dims[i].levels.begin(), dims[i].levels.end(), defaults[dims[i].name]),
                          dims[i].levels.end())
                    << structure << "." << dims[i].name;
            }
        }
    }
    // The levels a file gives are kept as given.
    const TuneSpec ug = parse_tune_spec(
        R"({"structures": ["ug"], "space": {"ug": {"density": [1, 2, 3]}}, "categories": [{"name": "c", "scenes": [{"preset": "uni-s"}]}]})",
        "t.json", ".");
    EXPECT_EQ(ug.space.at("ug")[0].levels, (std::vector<nlohmann::json>{1, 2, 3}));
}

TEST(TuneSpec, ScenesWithoutRaysAreRefusedNamingTheKey) {
    auto error = [](const std::string& text) {
        try {
            parse_tune_spec(text, "t.json", ".");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    EXPECT_EQ(
        error(
            R"({"structures": ["ug"], "rays_per_frame": 0, "categories": [{"name": "c", "scenes": [{"preset": "uni-s"}]}]})"),
        "t.json: rays_per_frame: 0 rays per frame in scene uni-s of category c: a tuning fits its cost model per "
        "ray cast, so it needs rays");
    EXPECT_EQ(
        error(
            R"({"structures": ["ug"], "categories": [{"name": "c", "scenes": [{"preset": "uni-s"}, {"preset": "uni-m", "rays_per_frame": 0}]}]})"),
        "t.json: categories[0].scenes[1].rays_per_frame: 0 rays per frame in scene uni-m of category c: a tuning fits "
        "its cost model per ray cast, so it needs rays");
}

/// A results database made by one short run, in rollback-journal mode as an older or copied file may be.
std::string small_database(const fs::path& dir, const std::string& name) {
    const fs::path exp = dir / (name + ".json");
    std::ofstream(exp)
        << R"({"name": ")" << name
        << R"(", "frames": 2, "rays_per_frame": 20, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})";
    const std::string db = (dir / (name + ".db")).string();
    EXPECT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--db", db}, (dir / "log.txt").string())), 0);
    Database(db, false).exec("PRAGMA journal_mode=DELETE");
    return db;
}

std::string file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(Store, ADamagedInputIsRefusedNamingItAndTheOutputIsLeftAsItWas) {
    const fs::path dir = test::temp_dir("runner", "damaged_merge");
    const std::string in = small_database(dir, "in"), out = small_database(dir, "out");
    {
        // Damage the frame table's primary-key index: an empty leaf page in place of its root,
        // so the table holds rows its index does not (pages a disk or a copy garbled).
        Database db(in, true);
        Statement root = db.prepare("SELECT rootpage FROM sqlite_master WHERE name = 'sqlite_autoindex_frame_1'");
        ASSERT_TRUE(root.step());
        const std::int64_t page = root.int64(0);
        Statement size = db.prepare("PRAGMA page_size");
        ASSERT_TRUE(size.step());
        std::fstream f(in, std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(std::streamoff((page - 1) * size.int64(0)));
        const char empty_leaf[8] = {0x0a, 0, 0, 0, 0, 0, 0, 0};
        f.write(empty_leaf, sizeof empty_leaf);
    }
    const std::string before = file_bytes(out);
    try {
        ResultStore store(out);
        merge_into(store, *open_read_only(in));
        ADD_FAILURE() << "merged a damaged database";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind(in + ": damaged results database (integrity check: ", 0), 0u) << e.what();
    }
    // Refused before anything was written: not even switched to WAL (the header's bytes 18-19).
    EXPECT_EQ(file_bytes(out), before);
    fs::remove_all(dir);
}

TEST(Store, MergeKeepsTheOrderCellsWereMeasuredIn) {
    // Cells are stored in the shuffled order they were measured in, and whatever reads them by id
    // (findings, the report) lists them so: a merged run reads as the run it came from.
    const test::TempDir temp("runner", "merge_order");
    const fs::path exp = temp.path() / "order.json";
    write_experiment(exp, 3);
    const std::string in = temp.file("in.db");
    ASSERT_EQ(wait_exit(spawn_rcbench({"run", exp.string(), "--db", in}, temp.file("log.txt"))), 0);
    {
        ResultStore store(temp.file("out.db"));
        merge_into(store, *open_read_only(in));
    }
    auto keys = [](const std::string& db) {
        Database d(db, true);
        Statement s = d.prepare(
            "SELECT cell_key || '/' || scene.name || '/' || repetition FROM cell JOIN scene ON scene.id = "
            "cell.scene_id ORDER BY cell.id");
        std::vector<std::string> out;
        while (s.step()) out.push_back(s.text(0));
        return out;
    };
    EXPECT_EQ(keys(temp.file("out.db")), keys(in));
}

TEST(Store, MergeLeavesFitsBehindAndSaysSo) {
    // A fit describes the cells it was fitted on: a shard's is a part of its run. The merge copies
    // the measurements, counts what it left, and the command says how to fit the merged run.
    const test::TempDir temp("runner", "merge_fits");
    const std::string in = small_database(temp.path(), "in");
    Database(in, false).exec(
        "INSERT INTO fit(run_id, created_at, structure, target, model, terms, observations, configurations, r2, "
        "rmse_relative, heldout_error, condition_number, status, chosen) VALUES (1, 'now', 'bf', 'raycast', "
        "'eq5.4', 'C_RB', 8, 1, 1, 0, 0, 1, 'ok', 1)");
    {
        ResultStore store(temp.file("lib.db"));
        const MergeCount n = merge_into(store, *open_read_only(in));
        EXPECT_EQ(n.runs, 1u);
        EXPECT_EQ(n.analyses, 1u);
    }
    EXPECT_EQ(count(temp.file("lib.db"), "SELECT count(*) FROM fit"), 0);
    EXPECT_EQ(count(temp.file("lib.db"), "SELECT count(*) FROM cell"), count(in, "SELECT count(*) FROM cell"));
    const std::string out = temp.file("out.db"), log = temp.file("merge.txt");
    ASSERT_EQ(wait_exit(spawn_rcbench({"merge", out, in}, log)), 0);
    EXPECT_NE(file_bytes(log).find(in + ": 1 new runs, " + std::to_string(count(in, "SELECT count(*) FROM cell")) +
                                   " new cells merged; its 1 fits, validations and derived categories are not "
                                   "copied (they describe its cells alone): rcbench fit " +
                                   out + " --run ID for each merged run"),
              std::string::npos)
        << file_bytes(log);
}

TEST(Store, TwoRunnersOfOnePlanMeasureEachCellOnce) {
    const fs::path dir = test::temp_dir("runner", "one_runner");
    const fs::path exp = dir / "resume.json";
    write_experiment(exp, 3);  // 6 cells
    const std::string db = (dir / "new.db").string();
    const std::string log_a = (dir / "a.txt").string(), log_b = (dir / "b.txt").string();
    const pid_t a = spawn_rcbench({"run", exp.string(), "--db", db}, log_a);
    const pid_t b = spawn_rcbench({"run", exp.string(), "--db", db}, log_b);
    ASSERT_EQ(wait_exit(a), 0);
    ASSERT_EQ(wait_exit(b), 0);
    // "run 1 of resume: 6 cells, D done before, R ran now": the two R add up to the plan, where
    // both used to measure every cell and throw one result of each away.
    auto ran = [](const std::string& log) {
        const std::string text = file_bytes(log);
        const std::size_t end = text.find(" ran now");
        if (end == std::string::npos) return std::int64_t(-1);
        const std::size_t start = text.rfind(", ", end) + 2;
        return std::int64_t(std::stoll(text.substr(start, end - start)));
    };
    EXPECT_EQ(ran(log_a) + ran(log_b), 6) << file_bytes(log_a) << file_bytes(log_b);
    EXPECT_EQ(count(db, "SELECT count(*) FROM run"), 1);
    EXPECT_EQ(count(db, "SELECT count(*) FROM cell"), 6);
    fs::remove_all(dir);
}

}  // namespace
}  // namespace rcb

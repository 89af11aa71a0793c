// Regression history over runs (runner/history.h): series per scene and configuration in run order,
// steps found where the level changes beyond the runs' noise and nowhere else, filters, errors, the
// report's History section and the `rcbench history` command.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>

#include "analysis/charts.h"
#include "analysis/report.h"
#include "core/base/error.h"
#include "accel/registry.h"
#include "runner/history.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "subprocess.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// Frame times as a busy machine gives them: each run has its own level (2% run-to-run spread),
/// each frame a log-normal 5% spread around it, and one frame in twenty is hit by something else
/// and takes 2-4 times as long.
std::vector<double> noisy_frames(std::mt19937_64& rng, double level_ns, std::size_t n) {
    std::normal_distribution<double> run_noise(0, 0.02), frame_noise(0, 0.05);
    std::uniform_real_distribution<double> u(0, 1);
    const double run_level = level_ns * std::exp(run_noise(rng));
    std::vector<double> out;
    for (std::size_t i = 0; i < n; ++i) {
        double t = run_level * std::exp(frame_noise(rng));
        if (u(rng) < 0.05) t *= 2 + 2 * u(rng);
        out.push_back(std::round(t));
    }
    return out;
}

/// Writes synthetic runs through the store API, as `rcbench run` would.
class SyntheticDb {
public:
    explicit SyntheticDb(const std::string& path) : store_(path) {}

    /// Starts a run of `experiment` made from `commit` at `started_at` by the program `binary` (this
    /// one when empty); returns its id.
    std::int64_t begin(const std::string& experiment, const std::string& commit, const std::string& started_at,
                       const std::string& binary = "") {
        Experiment e;
        e.name = experiment;
        e.content = "{}";
        e.hash = "hash-" + experiment;
        experiment_ = store_.experiment_id(e);
        RunInfo info = RunInfo::current(1, "", e);
        info.git_commit = commit;
        info.started_at = started_at;
        if (!binary.empty()) info.binary = binary;
        run_ = store_.begin_run(experiment_, info);
        return run_;
    }

    /// One measured cell of the current run.
    void cell(const std::string& scene, const std::string& structure, const std::vector<double>& raycast,
              const std::vector<double>& update) {
        SceneSpec spec;
        spec.name = scene;
        spec.key = {{"name", scene}};
        Recording r;
        r.initial.push_back(Object{1, {{0, 0, 0}, {1, 1, 1}}});
        SimulationResult res;
        res.structure = structure;
        res.params = find_structure(structure).defaults();
        res.objects = 1;
        for (std::size_t i = 0; i < raycast.size(); ++i) {
            FrameResult f;
            f.frame = std::uint32_t(i + 1);
            f.raycast_ns = std::uint64_t(raycast[i]);
            f.update_ns = std::uint64_t(update[i]);
            f.stats = nlohmann::json::object();
            res.frames.push_back(f);
        }
        Cell c;
        c.key = scene + "/" + structure;
        ASSERT_TRUE(store_.store_cell(run_, experiment_, c, spec, r, "scene-" + scene, res));
    }

    void finish() { store_.finish_run(run_); }

private:
    ResultStore store_;
    std::int64_t experiment_ = 0, run_ = 0;
};

const std::vector<std::string> kScenes{"small", "large"};
const std::vector<std::string> kStructures{"bf", "dbvh"};

std::string day(int i) { return "2026-01-" + std::string(i < 10 ? "0" : "") + std::to_string(i) + "T12:00:00Z"; }

/// Six runs of two scenes × two structures, 40 frames each; `factor(run, structure)` scales ray
/// cast (and `update_factor` update) in a run. Returns the run ids.
std::vector<std::int64_t> six_runs(SyntheticDb& db, std::uint64_t seed,
                                   const std::function<double(int, const std::string&)>& factor,
                                   const std::function<double(int, const std::string&)>& update_factor = {}) {
    std::mt19937_64 rng(seed);
    std::vector<std::int64_t> ids;
    for (int r = 1; r <= 6; ++r) {
        ids.push_back(db.begin("hist", "c0ffee" + std::to_string(r) + "abcdef", day(r)));
        for (const std::string& scene : kScenes)
            for (const std::string& structure : kStructures) {
                const double base = (scene == "large" ? 3e6 : 4e5) * (structure == "bf" ? 5 : 1);
                // Drawn in sequence (update, then ray cast): as two arguments of one call, GCC and
                // clang would draw them in opposite orders and the data would depend on the compiler.
                const std::vector<double> update =
                    noisy_frames(rng, 2e4 * (update_factor ? update_factor(r, structure) : 1.0), 40);
                const std::vector<double> raycast = noisy_frames(rng, base * factor(r, structure), 40);
                db.cell(scene, structure, raycast, update);
            }
        db.finish();
    }
    return ids;
}

std::size_t total_steps(const std::vector<HistorySeries>& series) {
    std::size_t n = 0;
    for (const HistorySeries& s : series) n += s.steps.size();
    return n;
}

TEST(History, FindsOneStepAtTheRunThatBecameSlower) {
    // Run 4 and every run after it are 20% slower: a regression introduced at run 4.
    for (std::uint64_t seed = 1; seed <= 5; ++seed) {
        const test::TempDir dir("history", "step" + std::to_string(seed));
        std::vector<std::int64_t> ids;
        {
            SyntheticDb db(dir.file("h.db"));
            ids = six_runs(db, seed, [](int r, const std::string&) { return r >= 4 ? 1.2 : 1.0; });
        }
        Database db(dir.file("h.db"), true);
        const std::vector<HistorySeries> series = load_history(db, {});
        ASSERT_EQ(series.size(), 4u);
        for (const HistorySeries& s : series) {
            SCOPED_TRACE("seed " + std::to_string(seed) + ", " + s.scene + " " + s.structure);
            EXPECT_EQ(s.experiment, "hist");
            ASSERT_EQ(s.points.size(), 6u);
            for (std::size_t i = 0; i < 6; ++i) {
                EXPECT_EQ(s.points[i].run, ids[i]);
                EXPECT_EQ(s.points[i].frames, 40u);
                EXPECT_EQ(s.points[i].started_at, day(int(i + 1)));
            }
            EXPECT_EQ(s.points[3].commit, "c0ffee4abcdef");
            EXPECT_GT(s.points[3].median_ns / s.points[2].median_ns, 1.1);
            ASSERT_EQ(s.steps.size(), 1u);
            const Step& step = s.steps[0];
            EXPECT_EQ(step.at, 3u);
            EXPECT_NEAR(step.change, 0.2, 0.05);
            EXPECT_LT(step.p_value, 0.01);
            EXPECT_GT(std::abs(step.after - step.before), 3 * step.noise);
        }
    }
}

TEST(History, PureNoiseHasNoStep) {
    // The same machine noise and no change: 5 seeds × 4 series × 2 metrics, and not one step.
    for (std::uint64_t seed = 1; seed <= 5; ++seed) {
        const test::TempDir dir("history", "noise" + std::to_string(seed));
        {
            SyntheticDb db(dir.file("h.db"));
            six_runs(db, 100 + seed, [](int, const std::string&) { return 1.0; });
        }
        Database db(dir.file("h.db"), true);
        HistoryQuery q;
        EXPECT_EQ(total_steps(load_history(db, q)), 0u) << "seed " << seed;
        q.metric = "update";
        EXPECT_EQ(total_steps(load_history(db, q)), 0u) << "seed " << seed;
    }
}

TEST(History, ASlowLastRunIsAStepAndAFasterRunIsANegativeStep) {
    const test::TempDir dir("history", "last");
    {
        SyntheticDb db(dir.file("h.db"));
        // dbvh: only the last run is 30% slower; bf: 25% faster from run 3 on.
        six_runs(db, 7, [](int r, const std::string& s) {
            return s == "dbvh" ? (r == 6 ? 1.3 : 1.0) : (r >= 3 ? 0.75 : 1.0);
        });
    }
    Database db(dir.file("h.db"), true);
    for (const HistorySeries& s : load_history(db, {})) {
        SCOPED_TRACE(s.scene + " " + s.structure);
        ASSERT_EQ(s.steps.size(), 1u);
        if (s.structure == "dbvh") {
            EXPECT_EQ(s.steps[0].at, 5u);
            EXPECT_NEAR(s.steps[0].change, 0.3, 0.06);
        } else {
            EXPECT_EQ(s.steps[0].at, 2u);
            EXPECT_NEAR(s.steps[0].change, -0.25, 0.05);
        }
    }
}

TEST(History, AOneRunBlipInsideTheHistoryIsNoLevelChange) {
    // One run alone 30% slower (a busy machine), the runs after it back: no level changed, wherever
    // inside the history the blip falls.
    for (int blip = 2; blip <= 5; ++blip) {
        const test::TempDir dir("history", "blip" + std::to_string(blip));
        {
            SyntheticDb db(dir.file("h.db"));
            six_runs(db, 10 + std::uint64_t(blip), [blip](int r, const std::string&) { return r == blip ? 1.3 : 1.0; });
        }
        Database db(dir.file("h.db"), true);
        EXPECT_EQ(total_steps(load_history(db, {})), 0u) << "blip at run " << blip;
    }
}

TEST(History, ALevelHeldByTwoRunsIsTwoSteps) {
    // Runs 3 and 4 slower, then fixed: up at run 3, down at run 5.
    const test::TempDir dir("history", "plateau");
    {
        SyntheticDb db(dir.file("h.db"));
        six_runs(db, 31, [](int r, const std::string&) { return r == 3 || r == 4 ? 1.25 : 1.0; });
    }
    Database db(dir.file("h.db"), true);
    for (const HistorySeries& s : load_history(db, {})) {
        SCOPED_TRACE(s.scene + " " + s.structure);
        ASSERT_EQ(s.steps.size(), 2u);
        EXPECT_EQ(s.steps[0].at, 2u);
        EXPECT_EQ(s.steps[1].at, 4u);
        EXPECT_GT(s.steps[0].change, 0.15);
        EXPECT_LT(s.steps[1].change, -0.12);
    }
}

TEST(History, FiltersSelectExperimentSceneStructureAndMetric) {
    const test::TempDir dir("history", "filters");
    {
        SyntheticDb db(dir.file("h.db"));
        // Ray cast unchanged; update of dbvh 40% slower from run 5 on.
        six_runs(
            db, 21, [](int, const std::string&) { return 1.0; },
            [](int r, const std::string& s) { return s == "dbvh" && r >= 5 ? 1.4 : 1.0; });
        // A second experiment with one scene and one structure, two runs.
        std::mt19937_64 rng(5);
        for (int r = 7; r <= 8; ++r) {
            db.begin("other", "beef" + std::to_string(r), day(r));
            const std::vector<double> update = noisy_frames(rng, 1e4, 20), raycast = noisy_frames(rng, 1e6, 20);
            db.cell("small", "bf", raycast, update);
            db.finish();
        }
    }
    Database db(dir.file("h.db"), true);
    EXPECT_EQ(load_history(db, {}).size(), 5u);  // every experiment
    HistoryQuery q;
    q.experiment = "other";
    const auto other = load_history(db, q);
    ASSERT_EQ(other.size(), 1u);
    EXPECT_EQ(other[0].experiment, "other");
    EXPECT_EQ(other[0].points.size(), 2u);

    q.experiment = "hist";
    q.scene = "large";
    auto large = load_history(db, q);
    ASSERT_EQ(large.size(), 2u);
    for (const HistorySeries& s : large) EXPECT_EQ(s.scene, "large");
    EXPECT_EQ(total_steps(large), 0u);  // ray cast did not change

    q.structure = "dbvh";
    q.metric = "update";
    const auto dbvh = load_history(db, q);
    ASSERT_EQ(dbvh.size(), 1u);
    EXPECT_EQ(dbvh[0].structure, "dbvh");
    EXPECT_EQ(dbvh[0].params, find_structure("dbvh").defaults().dump());
    ASSERT_EQ(dbvh[0].steps.size(), 1u);
    EXPECT_EQ(dbvh[0].steps[0].at, 4u);

    q.structure = "bf";
    EXPECT_EQ(total_steps(load_history(db, q)), 0u);  // bf's update did not change

    // Up to run 4: the update step at run 5 is not there yet.
    q.structure = "dbvh";
    q.up_to_run = 4;
    const auto early = load_history(db, q);
    ASSERT_EQ(early.size(), 1u);
    EXPECT_EQ(early[0].points.size(), 4u);
    EXPECT_EQ(early[0].points.back().run, 4);
    EXPECT_TRUE(early[0].steps.empty());
}

TEST(History, EachProgramsRunsAreASeriesOfTheirOwn) {
    // rcbench's runs, alternating with those of a program linking rcbench::cli whose build of bf is
    // 30% slower: one series mixing them would jump by 30% at every run; two series hold one level each.
    const test::TempDir dir("history", "programs");
    {
        SyntheticDb db(dir.file("h.db"));
        std::mt19937_64 rng(8);
        for (int d = 1; d <= 8; ++d) {
            const bool engine = d % 2 == 0;
            db.begin("hist", "c0ffee", day(d), engine ? "engine_bench" : "rcbench");
            const std::vector<double> update = noisy_frames(rng, 1e4, 30),
                                      raycast = noisy_frames(rng, engine ? 1.3e6 : 1e6, 30);
            db.cell("small", "bf", raycast, update);
            db.finish();
        }
    }
    Database db(dir.file("h.db"), true);
    const auto series = load_history(db, {});
    ASSERT_EQ(series.size(), 2u);
    for (const HistorySeries& s : series) {
        EXPECT_EQ(s.points.size(), 4u) << s.binary;
        EXPECT_TRUE(s.steps.empty()) << s.binary;
    }
    EXPECT_EQ(series[0].binary, "rcbench");
    EXPECT_EQ(series[1].binary, "engine_bench");
    HistoryQuery q;
    q.binary = "engine_bench";
    const auto engine = load_history(db, q);
    ASSERT_EQ(engine.size(), 1u);
    EXPECT_EQ(engine[0].binary, "engine_bench");
    EXPECT_EQ(engine[0].points.front().run, 2);
    q.binary = "other";
    EXPECT_NE(test::input_error_of([&] { load_history(db, q); }).find("no measured cells for binary 'other'"),
              std::string::npos);
}

TEST(History, RunOrderIsWhenTheRunsStartedNotTheirIds) {
    // A database merged from elsewhere: ids in one order, start times in another.
    const test::TempDir dir("history", "order");
    {
        SyntheticDb db(dir.file("h.db"));
        std::mt19937_64 rng(3);
        for (int d : {5, 2, 9, 1}) {
            const std::string commit = std::to_string(d);  // GCC 12 -Wrestrict misfires on "c" + a temporary
            db.begin("hist", "c" + commit, day(d));
            const std::vector<double> update = noisy_frames(rng, 1e4, 10), raycast = noisy_frames(rng, 1e6, 10);
            db.cell("small", "bf", raycast, update);
            db.finish();
        }
    }
    Database db(dir.file("h.db"), true);
    const auto series = load_history(db, {});
    ASSERT_EQ(series.size(), 1u);
    std::vector<std::string> commits;
    for (const HistoryPoint& p : series[0].points) commits.push_back(p.commit);
    EXPECT_EQ(commits, (std::vector<std::string>{"c1", "c2", "c5", "c9"}));
}

TEST(History, ErrorsNameWhatMatchedNothing) {
    const test::TempDir dir("history", "errors");
    {
        SyntheticDb db(dir.file("h.db"));
        six_runs(db, 1, [](int, const std::string&) { return 1.0; });
    }
    Database db(dir.file("h.db"), true);
    auto message = [&](const HistoryQuery& q) { return test::input_error_of([&] { load_history(db, q); }); };
    HistoryQuery q;
    q.experiment = "nope";
    EXPECT_NE(message(q).find("no experiment 'nope' (known: hist)"), std::string::npos) << message(q);
    q.experiment = "hist";
    q.scene = "missing";
    EXPECT_NE(message(q).find("no measured cells for experiment 'hist', scene 'missing'"), std::string::npos)
        << message(q);
    q.scene = "";
    q.structure = "lbvh";
    EXPECT_NE(message(q).find("no measured cells for experiment 'hist', structure 'lbvh'"), std::string::npos)
        << message(q);
    q.structure = "";
    q.up_to_run = 99;
    EXPECT_NE(message(q).find("no run 99"), std::string::npos) << message(q);
    q.up_to_run.reset();
    q.metric = "build";
    EXPECT_NE(message(q).find("unknown metric 'build'"), std::string::npos) << message(q);
}

TEST(History, DetectStepsOnPlainSamples) {
    EXPECT_TRUE(detect_steps({}).empty());
    EXPECT_TRUE(detect_steps({{1, 2, 3, 4, 5}}).empty());
    // Too few frames on a side to test: no step, however large.
    EXPECT_TRUE(detect_steps({{10, 10, 10}, {20, 20, 20}}).empty());
    // Quantised timers: no spread at all, and a clear shift.
    const std::vector<Step> flat =
        detect_steps({{100, 100, 100, 100, 100, 100}, {100, 100, 100, 100, 100, 100}, {130, 130, 130, 130, 130, 130}});
    ASSERT_EQ(flat.size(), 1u);
    EXPECT_EQ(flat[0].at, 2u);
    EXPECT_DOUBLE_EQ(flat[0].change, 0.3);
    // Two steps, up then down, each held for several runs.
    std::mt19937_64 rng(9);
    std::vector<std::vector<double>> runs;
    for (double level : {1.0, 1.0, 1.0, 1.5, 1.5, 1.5, 1.0, 1.0, 1.0})
        runs.push_back(noisy_frames(rng, 1e6 * level, 30));
    const std::vector<Step> two = detect_steps(runs);
    ASSERT_EQ(two.size(), 2u);
    EXPECT_EQ(two[0].at, 3u);
    EXPECT_EQ(two[1].at, 6u);
    EXPECT_GT(two[0].change, 0.4);
    EXPECT_LT(two[1].change, -0.25);
    // A stricter threshold than the shift leaves nothing.
    StepOptions strict;
    strict.k = 1e6;
    EXPECT_TRUE(detect_steps(runs, strict).empty());
}

TEST(History, ShortCommit) {
    EXPECT_EQ(short_commit("b87aa7c2fdd4-dirty"), "b87aa7c-dirty");
    EXPECT_EQ(short_commit("b87aa7c2fdd4"), "b87aa7c");
    EXPECT_EQ(short_commit("abc123"), "abc123");
    EXPECT_EQ(short_commit("unknown"), "unknown");
    EXPECT_EQ(short_commit("v1.2-3-gabc1234"), "v1.2-3-gabc1234");
}

/// A small real experiment run through the library into `db_path`; returns the run id.
std::int64_t small_run(const std::string& db_path) {
    const Experiment e = parse_experiment(
        R"({"name": "history-report", "frames": 6, "rays_per_frame": 100,
            "scenes": [{"generator": "uniform", "objects": 800}, {"generator": "irregular", "objects": 1500}],
            "structures": [{"name": "bf"}, {"name": "dbvh"}, {"name": "lbvh"}]})",
        "history-report.json", ".");
    RunOptions options;
    options.db = db_path;
    options.new_run = true;
    return run_experiment(e, "history-report.json", options).run;
}

std::string read(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(History, ReportHasAHistorySectionFromTheSecondRunOn) {
    ASSERT_TRUE(gnuplot_available())
        << "gnuplot is part of rcbench's dependencies (scripts/setup.sh installs gnuplot-nox)";
    const test::TempDir dir("history", "report");
    const std::string db_path = dir.file("r.db");
    const std::int64_t first = small_run(db_path);
    const std::int64_t second = small_run(db_path);
    Database db(db_path, true);

    const ReportSummary one = write_report(db, first, dir.file("first.html"));
    const std::string first_page = read(dir.file("first.html"));
    EXPECT_EQ(first_page.find("<h2>History</h2>"), std::string::npos);  // one run: no history yet

    const ReportSummary two = write_report(db, second, dir.file("second.html"));
    const std::string page = read(dir.file("second.html"));
    const auto at = page.find("<h2>History</h2>");
    ASSERT_NE(at, std::string::npos);
    EXPECT_EQ(two.charts, one.charts + 1);
    // The chart and its reading, computed from the data: two runs, and the steps found or none.
    const std::string section = page.substr(at);
    EXPECT_NE(section.find("<svg"), std::string::npos);
    EXPECT_NE(section.find("over the 2 runs up to this one"), std::string::npos) << section.substr(0, 2000);
    EXPECT_TRUE(section.find("No step beyond the runs' noise") != std::string::npos ||
                section.find("beyond the runs' noise in") != std::string::npos);
    // One line per configuration of the largest scene, with its run tics.
    for (const char* config : {"bf", "dbvh", "lbvh"}) EXPECT_NE(section.find(config), std::string::npos) << config;
}

TEST(History, CommandPrintsTheTableAndRefusesBadInput) {
    // Until cli/main.cpp adds the command, rcbench's help does not list it (and `rcbench history
    // --help` falls through to that help).
    const ::test::Outcome help = ::test::run_process({RCBENCH_BINARY, "--help"});
    if (help.out.find("\n  history ") == std::string::npos)
        GTEST_SKIP() << "rcbench has no history command yet (cli/main.cpp does not add it)";
    const test::TempDir dir("history", "cli");
    {
        SyntheticDb db(dir.file("h.db"));
        six_runs(db, 2, [](int r, const std::string& s) { return s == "dbvh" && r >= 4 ? 1.2 : 1.0; });
    }
    const std::string db = dir.file("h.db");
    const ::test::Outcome all = ::test::run_process({RCBENCH_BINARY, "history", db, "--experiment", "hist"});
    ASSERT_EQ(all.code, 0) << all.err;
    EXPECT_NE(all.out.find("run 1"), std::string::npos);
    EXPECT_NE(all.out.find("(c0ffee6)"), std::string::npos) << all.out;
    EXPECT_NE(all.out.find("step at run 4 (c0ffee4): +"), std::string::npos) << all.out;
    EXPECT_NE(all.out.find("2 steps in 4 series over 6 runs"), std::string::npos) << all.out;

    const ::test::Outcome bf = ::test::run_process(
        {RCBENCH_BINARY, "history", db, "--structure", "bf", "--scene", "small", "--metric", "update"});
    ASSERT_EQ(bf.code, 0) << bf.err;
    EXPECT_EQ(bf.out.find("dbvh"), std::string::npos);
    EXPECT_NE(bf.out.find("0 steps in 1 series over 6 runs"), std::string::npos) << bf.out;

    for (const std::vector<std::string>& bad :
         {std::vector<std::string>{dir.file("missing.db")}, std::vector<std::string>{db, "--experiment", "nope"},
          std::vector<std::string>{db, "--scene", "nope"}, std::vector<std::string>{db, "--metric", "build"},
          std::vector<std::string>{db, "--threshold", "nan"}}) {
        std::vector<std::string> argv{RCBENCH_BINARY, "history"};
        argv.insert(argv.end(), bad.begin(), bad.end());
        const ::test::Outcome o = ::test::run_process(argv);
        EXPECT_EQ(o.code, 2) << bad.back();
        EXPECT_TRUE(o.out.empty()) << o.out;
        EXPECT_EQ(std::count(o.err.begin(), o.err.end(), '\n'), 1) << o.err;
    }
}

}  // namespace
}  // namespace rcb

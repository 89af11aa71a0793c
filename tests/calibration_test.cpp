// The machine behind a run: cache sizes parsed from a sysfs folder (a fake one here), the
// calibration micro-scenes varying the counters as designed, and both stored once per run.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>

#include <cmath>

#include "analysis/cost_model.h"
#include "core/base/error.h"
#include "accel/registry.h"
#include "core/base/stopwatch.h"
#include "runner/calibration.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/forwarding_structure.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

void write_cache(const fs::path& dir, int index, const std::string& level, const std::string& type,
                 const std::string& size) {
    const fs::path d = dir / ("index" + std::to_string(index));
    fs::create_directories(d);
    std::ofstream(d / "level") << level << '\n';
    std::ofstream(d / "type") << type << '\n';
    std::ofstream(d / "size") << size << '\n';
}

TEST(CacheSizes, ParseFromASysfsFolder) {
    const test::TempDir temp("calibration", "sysfs");
    const fs::path& dir = temp.path();
    write_cache(dir, 0, "1", "Data", "48K");
    write_cache(dir, 1, "1", "Instruction", "32K");
    write_cache(dir, 2, "2", "Unified", "2048K");
    write_cache(dir, 3, "3", "Unified", "96M");
    const std::vector<CacheLevel> caches = read_cache_sizes(dir.string());
    ASSERT_EQ(caches.size(), 3u);  // the instruction cache is left out
    EXPECT_EQ(caches[0].level, 1);
    EXPECT_EQ(caches[0].type, "Data");
    EXPECT_EQ(caches[0].bytes, 48u << 10);
    EXPECT_EQ(caches[1].bytes, 2048u << 10);
    EXPECT_EQ(caches[2].level, 3);
    EXPECT_EQ(caches[2].bytes, 96u << 20);

    // A cold-cache run reads twice the largest cache before each update; 64 MiB when none is known.
    EXPECT_EQ(cold_sweep_bytes(caches), std::uint64_t(192) << 20);
    EXPECT_EQ(cold_sweep_bytes({}), std::uint64_t(64) << 20);

    EXPECT_TRUE(read_cache_sizes((dir / "absent").string()).empty());
    write_cache(dir, 4, "4", "Unified", "lots");
    test::expect_input_error([&] { read_cache_sizes(dir.string()); }, "index4/size");
}

TEST(CacheSizes, Units) {
    EXPECT_EQ(parse_cache_size("512", "x"), 512u);
    EXPECT_EQ(parse_cache_size("32K", "x"), 32u << 10);
    EXPECT_EQ(parse_cache_size("8M", "x"), 8u << 20);
    EXPECT_THROW(parse_cache_size("", "x"), InputError);
    EXPECT_THROW(parse_cache_size("K", "x"), InputError);
    EXPECT_THROW(parse_cache_size("12Q", "x"), InputError);
}

TEST(Calibration, MicroScenesVaryTheCountersIndependently) {
    for (const char* name : {"bf", "ug", "dbvh", "lbvh"}) {
        const StructureInfo& info = find_structure(name);
        const std::vector<CalibrationPoint> points = calibrate_structure(info, info.defaults(), 1);
        ASSERT_EQ(points.size(), 13u) << name;
        auto at = [&](const std::string& scene) {
            for (const CalibrationPoint& p : points)
                if (p.scene == scene) return p;
            ADD_FAILURE() << name << ": no micro-scene " << scene;
            return CalibrationPoint{};
        };
        EXPECT_EQ(at("stack").n_rb, 256) << name;  // every ray tests every box of the stack …
        EXPECT_EQ(at("stack").n_tp, 256) << name;  // … and reports it
        // The cluster: tests that seldom hit (C_RB apart from C_HIT); a grid's cells hold many.
        EXPECT_LT(at("cluster").n_tp, 0.1 * at("cluster").n_rb) << name;
        if (std::string(name) == "ug") {
            EXPECT_GT(at("cluster").n_rb, 20);
        }
        for (const CalibrationPoint& p : points) EXPECT_GT(p.ns_per_ray, 0) << name << " " << p.scene;
        if (std::string(name) == "bf") continue;  // brute force tests every box whatever the ray
        // Rays beside the world: a tree tests nothing (the grid keeps a few objects outside its cells).
        EXPECT_LT(at("outside-10").n_rb, std::string(name) == "ug" ? 10 : 1) << name;
        EXPECT_LT(at("shell").n_rb, 1) << name;  // rays inside the hollow shell meet no box …
        EXPECT_GE(at("shell").n_t, 4) << name;   // … but step through the structure
        // One ray repeated crosses the shell with as many steps, each predicted from the ray
        // before; random rays take paths the predictor cannot guess (C_MP's design): a tree's
        // node outcomes, a grid's ways out of its empty cells.
        EXPECT_GE(at("shell-coherent").n_t, 4) << name;
        EXPECT_LT(at("shell-coherent").n_mp, 0.1 * at("shell").n_mp) << name;
        EXPECT_GT(at("shell").n_mp, 1) << name;
    }
}

TEST(Calibration, OnlyTheLargeLatticeFetchesLines) {
    // Each timed batch is counted as it met the cache, after the batch before: a small scene's
    // structure stays cached, so its new rays fetch almost nothing, while the large lattice's
    // outgrow the simulated cache and fetch lines on every ray (C_MISS's design).
    for (const char* name : {"ug", "hg", "dbvh", "lbvh", "wbvh"}) {
        const StructureInfo& info = find_structure(name);
        const std::vector<CalibrationPoint> points = calibrate_structure(info, info.defaults(), 2);
        std::map<std::string, CalibrationPoint> at;
        for (const CalibrationPoint& p : points) at[p.scene] = p;
        ASSERT_EQ(at.count("scatter-32"), 1u) << name;
        EXPECT_GT(at["scatter-32"].n_miss, 2) << name;
        EXPECT_GT(at["short-32"].n_miss, 0.2) << name;
        for (const char* small : {"rows-10", "scatter-10", "shell", "stack"})
            EXPECT_LT(at[small].n_miss, 0.1 * at["scatter-32"].n_miss) << name << " " << small;
    }
}

TEST(Calibration, SameRaysAndCountsOnEveryRun) {
    // New rays per batch, but drawn from fixed seeds: two calibrations count alike.
    const StructureInfo& info = find_structure("lbvh");
    const std::vector<CalibrationPoint> a = calibrate_structure(info, info.defaults(), 2);
    const std::vector<CalibrationPoint> b = calibrate_structure(info, info.defaults(), 2);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
        EXPECT_EQ(a[i].n_rb, b[i].n_rb) << a[i].scene;
        EXPECT_EQ(a[i].n_t, b[i].n_t) << a[i].scene;
        EXPECT_EQ(a[i].n_mp, b[i].n_mp) << a[i].scene;
        EXPECT_EQ(a[i].n_miss, b[i].n_miss) << a[i].scene;
        EXPECT_EQ(a[i].n_tp, b[i].n_tp) << a[i].scene;
    }
}

/// Rays the slow list below was asked to cast (every query calls traverse once per ray).
std::uint64_t slow_casts = 0;

/// A deliberately slow structure: the tests' list (test::ToyList, 64 objects a block), spending
/// `spin_us` of its thread's CPU time on every ray first, so that each cast costs the calibration's
/// clock at least that much.
class SlowList : public test::Forwarding<SlowList, test::ToyList> {
public:
    struct Params {
        int spin_us = 0;
        static constexpr auto fields() {
            return std::tuple{Field{"spin_us", &Params::spin_us, 0, 10000, "CPU time spent per ray, in us"}};
        }
    };
    explicit SlowList(const Params& p) : Forwarding(test::ToyList::Params{64, false}), spin_us_(p.spin_us) {}

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        ++slow_casts;
        const Stopwatch spin;
        while (spin.elapsed().cpu_ns < std::uint64_t(spin_us_) * 1000u) {
        }
        inner_.traverse(s, count, visit);
    }

private:
    int spin_us_;
};

// rcbench's own structures are measured in full, whatever they take (their points stay as they were);
// one a program registers, or describes without registering, gets the budget.
TEST(CalibrationBudget, OnlyStructuresAProgramAddsHaveABudget) {
    for (const char* name : {"bf", "lbvh", "ode_hash", "ode_sap"})
        EXPECT_TRUE(std::isinf(calibration_budget(find_structure(name)))) << name;
    const StructureInfo slow = describe_structure<SlowList>("slow_list", "a list that spins per ray");
    EXPECT_EQ(calibration_budget(slow), kCalibrationBudgetSeconds);
}

// With its budget spent from the start, every micro-scene is one batch of kCutRays rays after a
// warm-up batch as large: a fixed number of casts, whatever the structure costs per ray.
TEST(CalibrationBudget, ASpentBudgetMeasuresEachSceneOnOneSmallBatch) {
    const StructureInfo info = describe_structure<SlowList>("slow_list", "a list that spins per ray");
    slow_casts = 0;
    const std::vector<CalibrationPoint> points = calibrate_structure(info, info.defaults(), 7, 0.0);
    ASSERT_EQ(points.size(), 13u);
    for (const CalibrationPoint& p : points) {
        EXPECT_EQ(p.rays, std::uint32_t(kCutRays)) << p.scene;
        EXPECT_EQ(p.repeats, 1) << p.scene;
        EXPECT_TRUE(p.cut) << p.scene;
        EXPECT_GT(p.ns_per_ray, 0) << p.scene;
    }
    // The cut batch is the first rays of the full one: the stack's rays all cross its 256 boxes.
    const auto stack = std::find_if(points.begin(), points.end(), [](const auto& p) { return p.scene == "stack"; });
    ASSERT_NE(stack, points.end());
    EXPECT_EQ(stack->n_rb, 256);
    EXPECT_EQ(stack->n_tp, 256);
    // Per scene: the warm-up, the timed batch, and the count of it after the warm-up (the warm-up
    // alone, then both as one batch).
    EXPECT_EQ(slow_casts, 13u * 5u * std::uint64_t(kCutRays));
}

// A structure that spends at least 100 us of CPU time on each ray (a full calibration asks it for
// 12 x 29 x 512 + 29 x 128 casts: 18 s) stops within its budget of 0.2 s plus the one scene under
// way when it ran out, and casts the remaining scenes' small batches: a bound in casts, which holds
// on any machine, since each cast spends at least its share of the budget.
TEST(CalibrationBudget, ASlowStructureStopsWithinItsBudgetInCasts) {
    const StructureInfo info = describe_structure<SlowList>("slow_list", "a list that spins per ray");
    constexpr double kBudget = 0.2;
    constexpr int kSpinUs = 100, kFull = 512;
    slow_casts = 0;
    const std::vector<CalibrationPoint> points =
        calibrate_structure(info, nlohmann::json{{"spin_us", kSpinUs}}, 7, kBudget);
    ASSERT_EQ(points.size(), 13u);
    const std::uint64_t within_budget = std::uint64_t(kBudget * 1e6 / kSpinUs);
    // The scene under way: its warm-up and 7 timed batches, then one counted (3 batches' casts).
    const std::uint64_t under_way = (1 + 7 + 3) * kFull;
    const std::uint64_t cut_scenes = 13u * 5u * std::uint64_t(kCutRays);
    EXPECT_LE(slow_casts, within_budget + under_way + cut_scenes);
    EXPECT_LT(slow_casts, (12u * 29u * kFull + 29u * 128u) / 10);
    // The first scene's 8 batches of 512 rays spend the budget: its point keeps one counted batch,
    // and every later scene is cut to one small batch.
    EXPECT_EQ(points[0].rays, std::uint32_t(kFull));
    EXPECT_EQ(points[0].repeats, 1);
    EXPECT_TRUE(points[0].cut);
    for (std::size_t i = 1; i < points.size(); ++i) {
        EXPECT_EQ(points[i].rays, std::uint32_t(kCutRays)) << points[i].scene;
        EXPECT_TRUE(points[i].cut) << points[i].scene;
    }
}

TEST(Calibration, StoredOncePerRun) {
    const test::TempDir temp("calibration", "run");
    const fs::path& dir = temp.path();
    const Experiment e = parse_experiment(
        R"({"frames": 2, "rays_per_frame": 50, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}, {"name": "dbvh", "params": {"mode": ["incremental", "rebuild"]}}]})",
        "exp.json", ".");
    RunOptions o;
    o.db = (dir / "r.db").string();
    const RunOutcome first = run_experiment(e, "exp.json", o);
    ResultStore store(o.db);
    auto count = [&](const char* table) {
        Statement s = store.db().prepare(std::string("SELECT count(*) FROM ") + table + " WHERE run_id = ?");
        s.bind(1, first.run);
        s.step();
        return s.int64(0);
    };
    EXPECT_EQ(load_calibration(store.db(), first.run, "bf").size(), 13u);
    EXPECT_EQ(load_calibration(store.db(), first.run, "dbvh").size(), 13u);  // one structure, one calibration
    for (const CalibrationPoint& p : load_calibration(store.db(), first.run, "dbvh")) {
        EXPECT_EQ(p.repeats, 7) << p.scene;  // rcbench's own: every batch timed and counted
        EXPECT_FALSE(p.cut) << p.scene;
    }
    EXPECT_EQ(count("calibration"), 26);
    EXPECT_EQ(std::size_t(count("run_cache")), read_cache_sizes().size());
    // Recording again (a resumed run) keeps what the run began with.
    EXPECT_FALSE(record_machine(store.db(), first.run, {{"bf", find_structure("bf").defaults()}}));
    EXPECT_EQ(count("calibration"), 26);
    // A merged run keeps its machine, so the merged database is fitted with the same priors.
    {
        ResultStore merged((dir / "merged.db").string());
        EXPECT_EQ(merge_into(merged, store.db()).runs, 1u);
        const std::vector<CalibrationPoint> a = load_calibration(store.db(), first.run, "dbvh");
        const std::vector<CalibrationPoint> b = load_calibration(merged.db(), 1, "dbvh");
        ASSERT_EQ(a.size(), b.size());
        for (std::size_t i = 0; i < a.size(); ++i) {
            EXPECT_EQ(a[i].scene, b[i].scene);
            EXPECT_EQ(a[i].ns_per_ray, b[i].ns_per_ray);
            EXPECT_EQ(a[i].n_miss, b[i].n_miss);
            EXPECT_EQ(a[i].n_tp, b[i].n_tp);
        }
        EXPECT_EQ(load_cache_sizes(merged.db(), 1).size(), read_cache_sizes().size());
    }
}

// A pass can fall in one of the host's slow stretches; passes spread over the run seldom all do, and
// the fit reads each micro-scene's fastest.
TEST(Calibration, PassesSpreadOverTheRunAndTheFastestIsRead) {
    const test::TempDir temp("calibration", "passes");
    const Experiment e = parse_experiment(
        R"({"frames": 2, "rays_per_frame": 50, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "ug", "params": {"density": [1, 2]}}]})",
        "exp.json", ".");
    RunOptions o;
    o.db = temp.file("r.db");
    o.calibration_spacing = std::chrono::seconds(0);  // a pass after every cell
    const RunOutcome out = run_experiment(e, "exp.json", o);
    EXPECT_EQ(out.calibrations, 3u);  // before the first cell and after each of the two
    std::vector<CalibrationPoint> before;
    {
        ResultStore store(o.db);
        EXPECT_EQ(test::count(store.db(), "SELECT count(DISTINCT pass) FROM calibration"), 3);
        EXPECT_EQ(test::count(store.db(), "SELECT count(*) FROM calibration"), 3 * 13);
        // The counters repeat between passes (fixed scenes and rays); only the times differ.
        EXPECT_EQ(
            test::count(store.db(),
                        "SELECT count(*) FROM (SELECT scene FROM calibration GROUP BY scene "
                        "HAVING count(DISTINCT n_rb) > 1 OR count(DISTINCT n_t) > 1 OR count(DISTINCT n_tp) > 1)"),
            0);
        before = load_calibration(store.db(), out.run, "ug");
        ASSERT_EQ(before.size(), 13u);
        for (const CalibrationPoint& p : before) {
            EXPECT_EQ(p.passes, 3) << p.scene;
            Statement fastest = store.db().prepare("SELECT min(ns_per_ray) FROM calibration WHERE scene = ?");
            fastest.bind(1, p.scene);
            fastest.step();
            EXPECT_EQ(p.ns_per_ray, fastest.real(0)) << p.scene;
        }
        // Made the stack's fastest in the middle pass, it is read from there; the order stays the
        // first pass's.
        store.db().exec("UPDATE calibration SET ns_per_ray = 0.25 WHERE pass = 1 AND scene = 'stack'");
        const std::vector<CalibrationPoint> after = load_calibration(store.db(), out.run, "ug");
        ASSERT_EQ(after.size(), before.size());
        for (std::size_t i = 0; i < after.size(); ++i) {
            EXPECT_EQ(after[i].scene, before[i].scene);
            EXPECT_EQ(after[i].ns_per_ray, after[i].scene == "stack" ? 0.25 : before[i].ns_per_ray);
        }
    }
    // Merging carries every pass; a run merged before its last pass gains it when merged again.
    const std::string part = temp.file("part.db");
    fs::copy_file(o.db, part);
    ResultStore(part).db().exec("DELETE FROM calibration WHERE pass = 2");
    ResultStore merged(temp.file("merged.db"));
    merge_into(merged, *open_read_only(part));
    EXPECT_EQ(load_calibration(merged.db(), 1, "ug").front().passes, 2);
    merge_into(merged, *open_read_only(o.db));
    const std::vector<CalibrationPoint> copied = load_calibration(merged.db(), 1, "ug");
    ASSERT_EQ(copied.size(), before.size());
    for (std::size_t i = 0; i < copied.size(); ++i) {
        EXPECT_EQ(copied[i].ns_per_ray, copied[i].scene == "stack" ? 0.25 : before[i].ns_per_ray) << copied[i].scene;
        EXPECT_EQ(copied[i].passes, 3) << copied[i].scene;
        EXPECT_EQ(copied[i].n_dup, before[i].n_dup) << copied[i].scene;  // the grid's dropped hits too
    }
    EXPECT_TRUE(std::any_of(before.begin(), before.end(), [](const CalibrationPoint& p) { return p.n_dup > 0; }));
}

TEST(Calibration, TheRunsFitUsesItAndStoresLeaveOneSceneOut) {
    const test::TempDir temp("calibration", "fit");
    const fs::path& dir = temp.path();
    const Experiment e = parse_experiment(
        R"({"frames": 3, "rays_per_frame": 100, "scenes": [{"preset": "uni-s"}, {"preset": "irreg-s"}, {"generator": "uniform", "objects": 300}], "structures": [{"name": "dbvh"}]})",
        "exp.json", ".");
    RunOptions o;
    o.db = (dir / "r.db").string();
    const RunOutcome outcome = run_experiment(e, "exp.json", o);
    ResultStore store(o.db);
    const RunFit fit = fit_run(store.db(), outcome.run);
    ASSERT_EQ(fit.models.size(), 1u);
    const StructureModels& m = fit.models[0];
    ASSERT_NE(m.calibration, nullptr);
    // Every micro-scene, but the cluster only where the calibration prices C_HIT with it.
    EXPECT_EQ(m.calibration->points.size(), m.calibration->term("C_HIT") ? 13u : 12u);
    EXPECT_EQ(m.loso.size(), 3u);  // every scene predicted from the two others
    const CandidateModel* chosen = m.chosen("raycast");
    ASSERT_NE(chosen, nullptr);
    for (const Coefficient& c : chosen->fit.coefficients) EXPECT_GT(c.value, 0) << c.name;  // none chosen at 0
    // Which form is chosen follows the measured times; every form fitted takes the calibration's
    // pinned value of a term as that coefficient's prior, and some form has such a term.
    int priors = 0;
    for (const CandidateModel& candidate : m.raycast)
        for (const Coefficient& c : candidate.fit.coefficients) {
            if (!std::isfinite(c.prior)) continue;
            const CalibratedTerm* t = m.calibration->term(c.name);
            ASSERT_NE(t, nullptr) << candidate.name << " " << c.name;
            EXPECT_TRUE(t->pinned) << candidate.name << " " << c.name;
            EXPECT_DOUBLE_EQ(c.prior, t->value) << candidate.name << " " << c.name;
            ++priors;
        }
    EXPECT_GT(priors, 0);  // the fit used the calibration
    Statement s = store.db().prepare(
        "SELECT loso_error FROM fit WHERE run_id = ? AND target = 'raycast' AND chosen = 1 AND loso_error IS NOT NULL");
    s.bind(1, outcome.run);
    ASSERT_TRUE(s.step());
    EXPECT_NEAR(s.real(0), m.loso_error, 1e-12);
}

}  // namespace
}  // namespace rcb

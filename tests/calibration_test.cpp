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
#include "runner/calibration.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"

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

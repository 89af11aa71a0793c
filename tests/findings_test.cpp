// The thesis' conclusions checked against a run (analysis/findings.h): each verdict follows from the
// measurements (synthetic cells with known times, memory and counters), a claim the run cannot test
// says so, and the Markdown carries every verdict.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include "analysis/findings.h"
#include "core/accel/registry.h"
#include "runner/store.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

struct Measured {
    double update_ms, ray_ms;
    double bytes_per_object = 100;
    double n_t = 10, n_rb = 20;
};

class FindingsDb {
public:
    explicit FindingsDb(const std::string& path) : store_(path) {
        Experiment e;
        e.name = "findings";
        e.content = "{}";
        e.hash = "hash-findings";
        experiment_ = store_.experiment_id(e);
        run_ = store_.begin_run(experiment_, RunInfo::current(1, "", e));
    }
    std::int64_t run() const { return run_; }

    void cell(const std::string& scene, const std::string& kind, std::size_t objects, const std::string& structure,
              const Measured& m, nlohmann::json params_override = nlohmann::json::object()) {
        SceneSpec spec;
        spec.name = scene;
        spec.key = {{"kind", kind}, {"objects", objects}};
        Recording r;
        r.initial.push_back(Object{1, {{0, 0, 0}, {1, 1, 1}}});
        SimulationResult res;
        res.structure = structure;
        res.params = find_structure(structure).defaults();
        res.params.update(params_override);
        res.objects = objects;
        res.memory_bytes = std::uint64_t(m.bytes_per_object * double(objects));
        for (std::uint32_t i = 1; i <= 5; ++i) {
            FrameResult f;
            f.frame = i;
            f.rays = 1000;
            f.update_ns = std::uint64_t(m.update_ms * 1e6);
            f.raycast_ns = std::uint64_t(m.ray_ms * 1e6);
            f.counters.n_t = std::uint64_t(m.n_t * 1000);
            f.counters.n_rb = std::uint64_t(m.n_rb * 1000);
            f.counters.n_tp = 1000;
            f.stats = nlohmann::json::object();
            res.frames.push_back(f);
        }
        Cell c;
        c.key = scene + "/" + structure + "/" + params_override.dump();
        ASSERT_TRUE(store_.store_cell(run_, experiment_, c, spec, r, "scene-" + scene, res));
    }
    void finish() { store_.finish_run(run_); }

private:
    ResultStore store_;
    std::int64_t experiment_ = 0, run_ = 0;
};

const Finding& by_source(const std::vector<Finding>& all, const std::string& words) {
    for (const Finding& f : all)
        if (f.claim.find(words) != std::string::npos) return f;
    throw std::runtime_error("no finding about " + words);
}

TEST(Findings, VerdictsFollowTheMeasurements) {
    const test::TempDir dir("findings", "verdicts");
    const fs::path path = dir.path() / "f.db";
    std::int64_t run = 0;
    {
        FindingsDb db(path.string());
        run = db.run();
        // A uniform scene where ug wins; an irregular one where the rebuilt dbvh wins and hg is 5% behind.
        db.cell("uni", "uniform", 5000, "bf", {0.01, 10.0});
        db.cell("uni", "uniform", 5000, "ug", {0.05, 0.50});
        db.cell("uni", "uniform", 5000, "hg", {0.10, 0.80, 900});
        db.cell("uni", "uniform", 5000, "dbvh", {0.10, 1.00});
        db.cell("uni", "uniform", 5000, "lbvh", {0.60, 0.55});
        db.cell("irr", "irregular", 5000, "bf", {0.01, 10.0});
        db.cell("irr", "irregular", 5000, "ug", {0.05, 2.00});
        db.cell("irr", "irregular", 5000, "hg", {0.10, 0.635, 900});
        db.cell("irr", "irregular", 5000, "dbvh", {0.10, 1.00, 100, 40, 20}, {{"mode", "incremental"}});
        db.cell("irr", "irregular", 5000, "dbvh", {0.10, 0.60, 100, 24, 20}, {{"mode", "rebuild"}});
        db.cell("irr", "irregular", 5000, "lbvh", {0.60, 0.62});
        // A small scene: the best structure barely beats brute force.
        db.cell("tiny", "uniform", 99, "bf", {0.001, 0.05});
        db.cell("tiny", "uniform", 99, "ug", {0.002, 0.04});
        db.finish();
    }
    Database db(path.string(), true);
    const std::vector<Finding> f = evaluate_findings(db, run);

    EXPECT_EQ(by_source(f, "uniform grid does very well").verdict, Finding::Verdict::confirmed);
    const Finding& hg = by_source(f, "larger irregular");
    EXPECT_EQ(hg.verdict, Finding::Verdict::partly);  // the rebuilt dbvh (0.70 ms) beats hg (0.735 ms)
    EXPECT_NE(hg.summary.find("irr: dbvh, hg +5%"), std::string::npos) << hg.summary;
    EXPECT_EQ(by_source(f, "LBVH casts fast").verdict, Finding::Verdict::confirmed);
    const Finding& sah = by_source(f, "full SAH");
    EXPECT_EQ(sah.verdict, Finding::Verdict::confirmed);  // 40% faster, as the thesis says
    EXPECT_NE(sah.summary.find("40%"), std::string::npos) << sah.summary;
    EXPECT_NE(sah.evidence.at(0).find("N_T 40.0 against 24.0"), std::string::npos) << sah.evidence.at(0);
    EXPECT_EQ(by_source(f, "far more memory").verdict, Finding::Verdict::confirmed);  // 9x the others
    EXPECT_EQ(by_source(f, "traversal step").verdict, Finding::Verdict::untested);    // no fit stored
    EXPECT_EQ(by_source(f, "small scenes").verdict, Finding::Verdict::confirmed);
    EXPECT_EQ(by_source(f, "most promising").verdict, Finding::Verdict::confirmed);  // dbvh then hg

    const std::string md = findings_markdown(db, run, f);
    EXPECT_NE(md.find("**partly confirmed**"), std::string::npos);
    EXPECT_NE(md.find("**not tested by this run**: No stored fit"), std::string::npos);
}

TEST(Findings, ARunWithoutTheNeededScenesTestsNothingItCannot) {
    const test::TempDir dir("findings", "empty");
    const fs::path path = dir.path() / "f.db";
    std::int64_t run = 0;
    {
        FindingsDb db(path.string());
        run = db.run();
        db.cell("only", "irregular", 99, "bf", {0.001, 0.05});
        db.finish();
    }
    Database db(path.string(), true);
    for (const Finding& f : evaluate_findings(db, run)) {
        EXPECT_EQ(f.verdict, Finding::Verdict::untested) << f.claim;
        EXPECT_FALSE(f.summary.empty()) << f.claim;
    }
}

}  // namespace
}  // namespace rcb

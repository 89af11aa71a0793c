// The thesis' conclusions checked against a run (analysis/findings.h): each verdict follows from the
// measurements (synthetic cells with known times, memory and counters), a claim the run cannot test
// says so, and the Markdown carries every verdict.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <tuple>

#include "analysis/findings.h"
#include "accel/registry.h"
#include "runner/store.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

struct Measured {
    double update_ms, ray_ms;
    double bytes_per_object = 100;
    double n_t = 10, n_rb = 20;
    std::vector<double> ray_ms_of_frame = {};  ///< when given, frame i's ray cast (five frames)
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
              const Measured& m, nlohmann::json params_override = nlohmann::json::object(),
              const std::string& ray_mix = "", std::uint32_t repetition = 0) {
        SceneSpec spec;
        spec.name = scene;
        spec.key = {{"kind", kind}, {"objects", objects}};
        if (!ray_mix.empty()) spec.key["ray_mix"] = ray_mix;
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
            f.raycast_ns = std::uint64_t((m.ray_ms_of_frame.empty() ? m.ray_ms : m.ray_ms_of_frame.at(i - 1)) * 1e6);
            f.counters.n_t = std::uint64_t(m.n_t * 1000);
            f.counters.n_rb = std::uint64_t(m.n_rb * 1000);
            f.counters.n_tp = 1000;
            f.stats = nlohmann::json::object();
            res.frames.push_back(f);
        }
        Cell c;
        c.repetition = repetition;
        c.key = scene + "/" + structure + "/" + params_override.dump() + "/" + std::to_string(repetition);
        ASSERT_TRUE(store_.store_cell(run_, experiment_, c, spec, r, "scene-" + scene, res));
    }
    void finish() { store_.finish_run(run_); }
    /// A stored fit of `model` for the ray cast (as `rcbench fit` stores every candidate form).
    void fit(const std::string& structure, const std::string& model, bool chosen, double c_t) {
        Database& db = store_.db();
        db.prepare(
              "INSERT INTO fit(run_id, created_at, structure, target, model, terms, observations, configurations, r2, "
              "rmse_relative, heldout_error, condition_number, status, chosen) VALUES "
              "(?, '2026-01-01T00:00:00Z', ?, 'raycast', ?, '[\"C_T\"]', 10, 2, 0.9, 0.1, 0.1, 1, 'ok', ?)")
            .bind_all(run_, structure, model, std::int64_t(chosen))
            .run();
        db.prepare("INSERT INTO fit_coefficient(fit_id, name, value, spans_zero) VALUES (?, 'C_T', ?, 0)")
            .bind_all(db.last_insert_id(), c_t)
            .run();
    }

private:
    ResultStore store_;
    std::int64_t experiment_ = 0, run_ = 0;
};

/// A run stored in `path`, its cells (and fits) written by `fill`, then finished; its id.
template <class Fill>
std::int64_t stored_run(const fs::path& path, Fill fill) {
    FindingsDb db(path.string());
    fill(db);
    db.finish();
    return db.run();
}

const Finding& by_source(const std::vector<Finding>& all, const std::string& words) {
    for (const Finding& f : all)
        if (f.claim.find(words) != std::string::npos) return f;
    throw std::runtime_error("no finding about " + words);
}

TEST(Findings, VerdictsFollowTheMeasurements) {
    const test::TempDir dir("findings", "verdicts");
    const fs::path path = dir.path() / "f.db";
    const std::int64_t run = stored_run(path, [&](FindingsDb& db) {
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
    });
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

    const std::string md = findings_markdown({{&db, run}});
    EXPECT_NE(md.find("**partly confirmed**"), std::string::npos);
    EXPECT_NE(md.find("**not tested by this run**: No stored fit"), std::string::npos);
}

// Each of hg's three repetitions was slowed on some frames, but every frame has a fast measurement:
// by each frame's fastest hg wins the irregular scene, by the median of its repetitions it does not.
TEST(Findings, ARunsTimeOfAConfigurationIsEachFramesFastestRepetition) {
    const test::TempDir dir("findings", "fastest");
    const fs::path path = dir.path() / "f.db";
    const std::int64_t run = stored_run(path, [&](FindingsDb& db) {
        db.cell("irr", "irregular", 5000, "bf", {0.01, 10.0});
        db.cell("irr", "irregular", 5000, "ug", {0.05, 2.00});
        db.cell("irr", "irregular", 5000, "dbvh", {0.10, 0.60});
        const std::vector<std::vector<double>> hg = {
            {0.9, 0.5, 0.9, 0.5, 0.9}, {0.5, 0.9, 0.5, 0.9, 0.5}, {0.9, 0.9, 0.9, 0.9, 0.9}};
        for (std::uint32_t rep = 0; rep < hg.size(); ++rep) {
            Measured m{0.10, 0.9};
            m.ray_ms_of_frame = hg[rep];
            db.cell("irr", "irregular", 5000, "hg", m, nlohmann::json::object(), "", rep);
        }
    });
    Database db(path.string(), true);
    const Finding fastest = by_source(evaluate_findings(db, run, OverRepetitions::fastest), "larger irregular");
    EXPECT_EQ(fastest.verdict, Finding::Verdict::confirmed) << fastest.summary;  // 0.60 ms against 0.70 ms
    // The default reads the ray cast the same way (only its update is the median over repetitions).
    const Finding cast = by_source(evaluate_findings(db, run), "larger irregular");
    EXPECT_EQ(cast.verdict, Finding::Verdict::confirmed) << cast.summary;
    const Finding median = by_source(evaluate_findings(db, run, OverRepetitions::median), "larger irregular");
    EXPECT_EQ(median.verdict, Finding::Verdict::refuted) << median.summary;  // 1.00 ms against 0.70 ms
    EXPECT_NE(findings_markdown({{&db, run}}, OverRepetitions::fastest).find("each frame's fastest time"),
              std::string::npos);
    EXPECT_NE(findings_markdown({{&db, run}}).find("each frame's fastest ray cast and median update"),
              std::string::npos);
}

// Three runs of one experiment: figures are medians over the runs with their range, the verdict is
// read on those medians, and each run alone is read too (the third disagrees here).
TEST(Findings, SeveralRunsGiveMediansRangesAndEachRunsVerdict) {
    const test::TempDir dir("findings", "runs");
    const fs::path path = dir.path() / "f.db";
    std::vector<std::int64_t> ids;
    for (double ug_rays : {0.50, 0.52, 0.90}) {
        FindingsDb db(path.string());
        ids.push_back(db.run());
        db.cell("uni", "uniform", 5000, "ug", {0.05, ug_rays});
        db.cell("uni", "uniform", 5000, "hg", {0.10, 0.70});
        db.finish();
    }
    Database db(path.string(), true);
    const std::vector<FindingsRun> runs{{&db, ids[0]}, {&db, ids[1]}, {&db, ids[2]}};
    const std::vector<Finding> f = evaluate_findings(runs);
    const Finding& ug = by_source(f, "uniform grid does very well");
    EXPECT_EQ(ug.verdict, Finding::Verdict::confirmed);  // median ug 0.57 ms against hg 0.80 ms
    EXPECT_EQ(ug.per_run, (std::vector<Finding::Verdict>{Finding::Verdict::confirmed, Finding::Verdict::confirmed,
                                                         Finding::Verdict::refuted}));
    ASSERT_FALSE(ug.evidence.empty());
    EXPECT_NE(ug.evidence[0].find("ug 0.570 ms [0.550–0.950]"), std::string::npos) << ug.evidence[0];
    const std::string md = findings_markdown(runs);
    EXPECT_NE(md.find("from 3 independent runs of experiment `findings`"), std::string::npos);
    EXPECT_NE(md.find("Each run alone: 2 of 3 give this verdict (confirmed, confirmed, refuted)."), std::string::npos);
    EXPECT_NE(md.find("Configurations measured: ug defaults; hg defaults."), std::string::npos);
    // One run reads as before: no range, no count of runs.
    const std::vector<Finding> one = evaluate_findings(db, ids[2]);
    EXPECT_EQ(by_source(one, "uniform grid does very well").verdict, Finding::Verdict::refuted);
    EXPECT_EQ(findings_markdown({{&db, ids[2]}}).find("Each run alone"), std::string::npos);
}

// Cells are measured in a shuffled order; the findings list scenes smallest first and each scene's
// structures in one fixed order, so two runs measured in different orders read alike.
TEST(Findings, ScenesAndStructuresAreListedInOneOrderWhateverTheMeasuringOrder) {
    const test::TempDir dir("findings", "order");
    const fs::path path = dir.path() / "f.db";
    using Stored = std::tuple<std::string, std::size_t, std::string>;
    auto run_in = [&](const std::vector<Stored>& order) {
        return stored_run(path, [&](FindingsDb& db) {
            for (const auto& [scene, objects, structure] : order)
                db.cell(scene, "uniform", objects, structure, {structure == "ug" ? 0.05 : 0.10, 0.5});
        });
    };
    const std::int64_t a =
        run_in({{"uni-l", 14000, "hg"}, {"uni-l", 14000, "ug"}, {"uni-m", 5000, "hg"}, {"uni-m", 5000, "ug"}});
    const std::int64_t b =
        run_in({{"uni-m", 5000, "ug"}, {"uni-l", 14000, "ug"}, {"uni-m", 5000, "hg"}, {"uni-l", 14000, "hg"}});
    Database db(path.string(), true);
    const std::vector<Finding> fa = evaluate_findings(db, a), fb = evaluate_findings(db, b);
    const Finding& memory_a = by_source(fa, "far more memory");
    const Finding& memory_b = by_source(fb, "far more memory");
    ASSERT_EQ(memory_a.evidence.size(), 2u);
    EXPECT_EQ(memory_a.evidence, memory_b.evidence);
    EXPECT_EQ(memory_a.evidence[0].rfind("uni-m, bytes per object: hg 100, ug 100", 0), 0u) << memory_a.evidence[0];
    EXPECT_NE(findings_markdown({{&db, b}}).find("Configurations measured: ug defaults; hg defaults."),
              std::string::npos);
}

// Over several runs, a scene only a later run measured goes where its size puts it, not last; a
// structure's configurations go by their parameters' values, numbers as numbers.
TEST(Findings, MergedRunsAndParameterValuesKeepTheListingOrder) {
    const test::TempDir dir("findings", "merged-order");
    const fs::path path = dir.path() / "f.db";
    auto scenes = [](FindingsDb& db, bool with_smaller) {
        for (const char* structure : {"hg", "ug"}) {
            db.cell("uni-l", "uniform", 14000, structure, {0.10, 0.5});
            if (with_smaller) db.cell("uni-m", "uniform", 5000, structure, {0.10, 0.5});
        }
        for (double density : {16.0, 1.0})
            db.cell("uni-l", "uniform", 14000, "ug", {0.10, 0.5}, {{"density", density}});
    };
    const std::int64_t a = stored_run(path, [&](FindingsDb& db) { scenes(db, false); });
    const std::int64_t b = stored_run(path, [&](FindingsDb& db) { scenes(db, true); });
    Database db(path.string(), true);
    const std::vector<FindingsRun> runs{{&db, a}, {&db, b}};
    const std::vector<Finding> findings = evaluate_findings(runs);
    const Finding& memory = by_source(findings, "far more memory");
    ASSERT_EQ(memory.evidence.size(), 2u);
    EXPECT_EQ(memory.evidence[0].rfind("uni-m,", 0), 0u) << memory.evidence[0];
    EXPECT_EQ(memory.evidence[1].rfind("uni-l,", 0), 0u) << memory.evidence[1];
    const std::string md = findings_markdown(runs);
    EXPECT_NE(md.find("ug density 1.0/4.0/16.0"), std::string::npos) << md;  // 4.0: the defaults
}

// Chosen forms differ per structure (a form with more terms moves C_T by what they take), so the
// traversal costs are compared under eq. 5.4 for all: here the chosen forms would say the opposite.
TEST(Findings, TraversalCostsAreComparedUnderOneForm) {
    const test::TempDir dir("findings", "form");
    const fs::path path = dir.path() / "f.db";
    const std::int64_t run = stored_run(path, [&](FindingsDb& db) {
        db.cell("irr", "irregular", 5000, "ug", {0.05, 0.5});
        db.cell("irr", "irregular", 5000, "dbvh", {0.05, 0.4});
        db.fit("ug", "per-category", true, 20.0);
        db.fit("ug", "eq5.4", false, 3.0);
        db.fit("dbvh", "with-memory", true, 1.0);
        db.fit("dbvh", "eq5.4", false, 5.0);
    });
    Database db(path.string(), true);
    const std::vector<Finding> f = evaluate_findings(db, run);
    const Finding& t = by_source(f, "traversal step");
    EXPECT_EQ(t.verdict, Finding::Verdict::confirmed) << t.summary;
    ASSERT_FALSE(t.evidence.empty());
    EXPECT_NE(t.evidence[0].find("dbvh 5.00 ns; ug 3.00 ns;"), std::string::npos) << t.evidence[0];
}

// The thesis cast dense rays for Table 6.4: where the run has a dense-ray scene the full-SAH claim is
// read there alone, and that scene stays out of the claims of Table 6.2.
TEST(Findings, DenseRaysDecideTheFullSahClaimAndStayOutOfTheOthers) {
    const test::TempDir dir("findings", "dense");
    const fs::path path = dir.path() / "f.db";
    const std::int64_t run = stored_run(path, [&](FindingsDb& db) {
        db.cell("irr", "irregular", 5000, "hg", {0.10, 0.50});
        db.cell("irr", "irregular", 5000, "dbvh", {0.10, 1.00}, {{"mode", "incremental"}});
        db.cell("irr", "irregular", 5000, "dbvh", {0.10, 1.00}, {{"mode", "rebuild"}});
        db.cell("irr-dense", "irregular", 5000, "dbvh", {0.10, 1.00}, {{"mode", "incremental"}}, "dense");
        db.cell("irr-dense", "irregular", 5000, "dbvh", {0.10, 0.60}, {{"mode", "rebuild"}}, "dense");
        db.cell("irr-dense", "irregular", 5000, "hg", {0.10, 2.00}, nlohmann::json::object(), "dense");
    });
    Database db(path.string(), true);
    const std::vector<Finding> f = evaluate_findings(db, run);
    const Finding& sah = by_source(f, "full SAH");
    EXPECT_EQ(sah.verdict, Finding::Verdict::confirmed) << sah.summary;  // 40% on dense rays, 0% on centre rays
    EXPECT_NE(sah.summary.find("with dense rays"), std::string::npos) << sah.summary;
    ASSERT_EQ(sah.evidence.size(), 1u);
    EXPECT_EQ(sah.evidence[0].rfind("irr-dense:", 0), 0u) << sah.evidence[0];
    const Finding& hg = by_source(f, "larger irregular");
    EXPECT_EQ(hg.verdict, Finding::Verdict::confirmed) << hg.summary;  // irr only; on irr-dense dbvh wins
    const std::string md = findings_markdown({{&db, run}});
    EXPECT_NE(md.find("Configurations measured: dbvh mode incremental/rebuild; hg defaults."), std::string::npos) << md;
}

TEST(Findings, ARunWithoutTheNeededScenesTestsNothingItCannot) {
    const test::TempDir dir("findings", "empty");
    const fs::path path = dir.path() / "f.db";
    const std::int64_t run = stored_run(path, [&](FindingsDb& db) {
        db.cell("only", "irregular", 99, "bf", {0.001, 0.05});
    });
    Database db(path.string(), true);
    for (const Finding& f : evaluate_findings(db, run)) {
        EXPECT_EQ(f.verdict, Finding::Verdict::untested) << f.claim;
        EXPECT_FALSE(f.summary.empty()) << f.claim;
    }
}

}  // namespace
}  // namespace rcb

// The cost model validated on what it never saw (analysis/validation.h): a held-out scene cannot
// choose its own model in the nested splits; a model frozen on one run predicts another run's
// frames as well as their noise allows; the bootstrap interval narrows with more scenes; and
// `rcbench validate` stores its results and refuses bad input with exit 2.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "analysis/validation.h"
#include "core/base/random.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

constexpr double kRb = 2.0, kT = 4.0, kPrep = 30.0, kMove = 500.0, kFrame = 2000.0;

/// One configuration's frames of structure `structure` in scene `scene`: ray cast from the known
/// costs (plus `offset` ns per ray), update 500 ns per move + 2000, each with relative noise `noise`.
void add_cell(std::vector<FrameObservation>& out, const std::string& structure, const std::string& scene, int group,
              double n_rb, double n_t, double offset, double noise, Random& rng) {
    for (int f = 0; f < 8; ++f) {
        FrameObservation o;
        o.structure = structure;
        o.scene = scene;
        o.category = "irregular";
        o.ray_mix = "center";
        o.params = "{}";
        o.config_group = group;
        o.rays = 1000;
        o.n_rb = n_rb;
        o.n_t = n_t;
        o.objects = 1000 + group;
        o.raycast_ns = o.rays * (kRb * n_rb + kT * n_t + offset) * (1 + noise * rng.normal());
        o.moves = 50 + 10 * (group % 7);
        o.update_ns = (kMove * o.moves + kFrame) * (1 + noise * rng.normal());
        out.push_back(o);
    }
}

/// `scenes` scenes of `configs` configurations each, counters drawn independently over [lo, hi].
std::vector<FrameObservation> known_run(std::uint64_t seed, int scenes, int configs, double lo, double hi, double noise,
                                        const std::string& structure = "tree") {
    Random rng(seed);
    std::vector<FrameObservation> out;
    int group = 0;
    for (int s = 0; s < scenes; ++s)
        for (int c = 0; c < configs; ++c, ++group)
            add_cell(out, structure, "scene" + std::to_string(s), group, rng.log_uniform(lo, hi),
                     rng.log_uniform(lo, hi), kPrep, noise, rng);
    return out;
}

const ValidationSplit& split_named(const std::vector<ValidationSplit>& splits, const std::string& name) {
    const auto it =
        std::find_if(splits.begin(), splits.end(), [&](const ValidationSplit& s) { return s.name == name; });
    if (it == splits.end()) throw std::logic_error("no split " + name);
    return *it;
}

TEST(NestedValidation, OneFamilyCannotChooseAFormForItself) {
    // Every scene counts unpredicted steps (N_MP), but only in the family of "x" (x and its
    // centre-ray twin) do they cost anything (20 ns each). The inner k-fold holds the twins out
    // together, so no fold learns C_MP from one twin and is scored on the other: the family alone
    // cannot make with-coherence win, and eq. 5.4 is kept.
    Random rng(11);
    std::vector<FrameObservation> frames;
    int group = 0;
    for (const std::string scene : {"scene0", "scene1", "scene2", "scene3", "scene4", "x", "x-center"})
        for (int c = 0; c < 4; ++c, ++group)
            add_cell(frames, "tree", scene, group, rng.log_uniform(100, 2000), rng.log_uniform(100, 2000), kPrep, 0.01,
                     rng);
    for (FrameObservation& f : frames) {
        f.n_mp = (0.2 + 0.1 * (f.config_group % 4)) * f.n_t;
        if (f.scene[0] == 'x') f.raycast_ns += f.rays * 20.0 * f.n_mp;
    }
    const std::vector<StructureModels> all = fit_cost_models(frames);
    ASSERT_NE(all.at(0).chosen("raycast"), nullptr);
    EXPECT_EQ(all.at(0).chosen("raycast")->name, "eq5.4");

    const std::vector<ValidationSplit> splits = family_out_splits(frames);
    ASSERT_EQ(splits.size(), 6u);
    const std::vector<CellPrediction> x = run_split(frames, split_named(splits, "x"), {});
    ASSERT_EQ(x.size(), 8u);  // both twins held out
    for (const CellPrediction& c : x) {
        EXPECT_EQ(c.scene[0], 'x');
        EXPECT_EQ(c.raycast_model, "eq5.4");
        EXPECT_GT(c.raycast_error, 0.3);  // the cost it needs is missing
    }
}

TEST(NestedValidation, SplitsAreDataAndNeverLeakTheTestFrames) {
    std::vector<FrameObservation> frames = known_run(3, 4, 2, 100, 1000, 0.01);
    for (FrameObservation& f : frames) {
        if (f.scene == "scene3") f.objects = 1e6;  // the largest
        if (f.scene == "scene0" || f.scene == "scene1") f.category = "uniform";
        if (f.scene == "scene1") f.ray_mix = "dense";
    }
    const std::vector<ValidationSplit> splits = nested_splits(frames);
    std::map<std::string, int> groups;
    for (const ValidationSplit& s : splits) {
        ++groups[s.group];
        EXPECT_FALSE(s.train.empty()) << s.name;
        EXPECT_FALSE(s.test.empty()) << s.name;
        for (std::size_t i : s.test) EXPECT_EQ(std::count(s.train.begin(), s.train.end(), i), 0) << s.name;
    }
    EXPECT_EQ(groups[kFamilyOutGroup], 4);
    EXPECT_EQ(groups["leave-one-generator-out"], 2);
    EXPECT_EQ(groups["leave-the-largest-out"], 1);
    EXPECT_EQ(groups["ray modes center -> dense"], 1);
    EXPECT_EQ(groups["ray modes dense -> center"], 1);
    EXPECT_EQ(split_named(splits, "scene3 (1000000 objects)").test.size(), 16u);
    EXPECT_EQ(split_named(splits, "ray modes dense -> center").train.size(), 16u);
}

TEST(TransferValidation, AFrozenModelPredictsAnotherRunWithinItsNoise) {
    // Run A: 8 scenes; run B: other scenes, counters over another range, and a structure A lacks.
    const std::vector<FrameObservation> a = known_run(5, 8, 3, 50, 2000, 0.02);
    std::vector<FrameObservation> b = known_run(6, 6, 3, 100, 5000, 0.02);
    const std::vector<FrameObservation> other = known_run(7, 2, 1, 100, 1000, 0.02, "unknown");
    for (FrameObservation f : other) {
        f.config_group += 1000;
        b.push_back(f);
    }
    const std::vector<StructureModels> models = fit_cost_models(a);
    const CandidateModel* m = models.at(0).chosen("raycast");
    ASSERT_NE(m, nullptr);
    EXPECT_NEAR(fitted_value(m->fit.coefficients, "C_RB", ""), kRb, 0.05 * kRb);
    EXPECT_NEAR(fitted_value(m->fit.coefficients, "C_T", ""), kT, 0.05 * kT);

    const TransferValidation v = validate_transfer(models, b, {500, 3});
    EXPECT_EQ(v.unpredictable, std::vector<std::string>{"unknown"});
    ASSERT_EQ(v.group.structures.size(), 2u);  // in name order
    const StructureValidation &tree = v.group.structures[0], &unknown = v.group.structures[1];
    ASSERT_EQ(tree.structure, "tree");
    EXPECT_EQ(tree.cells, 18u);
    EXPECT_EQ(tree.unpredictable, 0u);
    EXPECT_EQ(tree.scenes, 6u);
    // A cell's error is its median frame's: 8 frames of 2% noise, and the fit's own error.
    EXPECT_LT(tree.raycast.median, 0.02);
    EXPECT_LT(tree.frame.median, 0.02);
    EXPECT_LT(tree.raycast.p90, 0.04);
    EXPECT_LE(tree.raycast.median_low, tree.raycast.median);
    EXPECT_GE(tree.raycast.median_high, tree.raycast.median);
    EXPECT_EQ(unknown.unpredictable, 2u);  // listed, never priced: misses
    EXPECT_EQ(unknown.misses, 2u);
    EXPECT_TRUE(std::isinf(unknown.frame.median));
}

TEST(CalibrationOnly, PricesTheRayCastFromTheCalibrationAloneAndNeverTheUpdate) {
    std::vector<FrameObservation> frames = known_run(9, 3, 2, 50, 2000, 0.0);
    Random rng(3);
    add_cell(frames, "uncalibrated", "scene0", 100, 100, 100, kPrep, 0.0, rng);
    ModelInputs inputs;
    StructureCalibration c;
    c.structure = "tree";
    for (const auto& [name, value] : {std::pair{"C_RB", kRb}, {"C_T", kT}, {"C_PREP", kPrep}})
        c.terms.push_back({name, value, value, value, true, ""});
    inputs.calibrations.push_back(c);
    ValidationGroup g = validate_calibration_only(frames, inputs, {50, 1});
    EXPECT_EQ(g.name, "calibration-only");
    ASSERT_EQ(g.structures.size(), 2u);
    const StructureValidation& tree = g.structures[0];
    EXPECT_EQ(tree.structure, "tree");
    EXPECT_EQ(tree.cells, 6u);
    EXPECT_EQ(tree.unpredictable, 0u);
    EXPECT_LT(tree.raycast.p90, 1e-12);          // the calibration's costs are the scene's
    EXPECT_TRUE(std::isnan(tree.frame.median));  // updates are not calibrated
    EXPECT_EQ(g.structures[1].unpredictable, 1u);
    // A calibration that misprices C_T by half shows up as the error it makes.
    inputs.calibrations[0].terms[1].value = kT / 2;
    g = validate_calibration_only(frames, inputs, {50, 1});
    EXPECT_GT(g.structures[0].raycast.median, 0.05);
    // Lines fetched: priced where the micro-scenes fitted C_MISS, as every term with a prior.
    inputs.calibrations[0].terms[1].value = kT;
    for (FrameObservation& f : frames) f.n_miss = 30, f.raycast_ns += f.rays * 30 * 20.0;
    g = validate_calibration_only(frames, inputs, {50, 1});
    EXPECT_GT(g.structures[0].raycast.median, 0.05);
    inputs.calibrations[0].terms.push_back({"C_MISS", 20.0, 20.0, 20.0, true, ""});
    g = validate_calibration_only(frames, inputs, {50, 1});
    EXPECT_LT(g.structures[0].raycast.p90, 1e-12);
}

TEST(Bootstrap, TheIntervalNarrowsAsScenesGrow) {
    const auto width = [](int scenes) {
        Random rng(21);
        std::vector<CellPrediction> cells;
        for (int s = 0; s < scenes; ++s) {
            const double scene_bias = 0.05 * std::abs(rng.normal());  // cells of a scene err alike
            for (int c = 0; c < 3; ++c) {
                CellPrediction p;
                p.structure = "tree", p.scene = "s" + std::to_string(s), p.split = p.scene;
                p.predicted_frame_ns = 1;
                p.frame_error = p.raycast_error = scene_bias + 0.01 * std::abs(rng.normal());
                cells.push_back(p);
            }
        }
        const StructureValidation v = summarize(cells, {2000, 9}).at(0);
        EXPECT_LE(v.frame.median_low, v.frame.median);
        EXPECT_GE(v.frame.median_high, v.frame.median);
        return v.frame.median_high - v.frame.median_low;
    };
    const double few = width(5), some = width(20), many = width(80);
    EXPECT_GT(few, some);
    EXPECT_GT(some, many);
    EXPECT_GT(many, 0);
}

TEST(Bootstrap, QuantilesInterpolateAndTheSeedRepeats) {
    EXPECT_DOUBLE_EQ(quantile({4, 1, 3, 2}, 0.5), 2.5);
    EXPECT_DOUBLE_EQ(quantile({1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11}, 0.9), 10);
    EXPECT_TRUE(std::isnan(quantile({}, 0.5)));
    std::vector<CellPrediction> cells;
    for (int s = 0; s < 6; ++s) {
        CellPrediction p;
        p.structure = "tree", p.scene = "s" + std::to_string(s), p.predicted_frame_ns = 1;
        p.frame_error = 0.01 * s;
        cells.push_back(p);
    }
    const StructureValidation one = summarize(cells, {300, 4}).at(0), two = summarize(cells, {300, 4}).at(0);
    EXPECT_EQ(one.frame.median_low, two.frame.median_low);
    EXPECT_EQ(one.frame.p90_high, two.frame.p90_high);
}

TEST(SceneFamily, TwinsShareAFamilyAndOtherScenesDoNot) {
    EXPECT_EQ(scene_family("oa_dm4-brushes"), "oa_dm4");
    EXPECT_EQ(scene_family("oa_dm4-triangles"), "oa_dm4");
    // A model's representations (scene import --model-mode) are one family too.
    EXPECT_EQ(scene_family("2CylinderEngine-instances"), "2CylinderEngine");
    EXPECT_EQ(scene_family("2CylinderEngine-obbs"), "2CylinderEngine");
    EXPECT_EQ(scene_family("g-track-2-triangles"), "g-track-2");
    EXPECT_EQ(scene_family("instances-2000"), "instances-2000");  // only as the last segment
    EXPECT_EQ(scene_family("irregular-center-2000"), "irregular-2000");
    EXPECT_EQ(scene_family("irregular-2000"), "irregular-2000");
    EXPECT_EQ(scene_family("irreg-l-dense"), "irreg-l");
    EXPECT_EQ(scene_family("uniform-center"), "uniform");
    EXPECT_EQ(scene_family("irregular-2000-s3"), "irregular-2000");
    EXPECT_EQ(scene_family("uni-l"), "uni-l");
    EXPECT_EQ(scene_family("center"), "center");  // all ray modes: its own family
    EXPECT_NE(scene_family("irregular-40000"), scene_family("irregular-2000"));
    EXPECT_NE(scene_family("oa_dm1-brushes"), scene_family("oa_dm4-brushes"));
}

/// Frames of twins and loners: a map's brushes and triangles, a generator's ray-mode variants, a
/// scene of its own; each scene 3 configurations.
std::vector<FrameObservation> twin_run() {
    Random rng(17);
    std::vector<FrameObservation> frames;
    int group = 0;
    for (const char* scene :
         {"m-brushes", "m-triangles", "gen-2000", "gen-center-2000", "other", "gen-40000", "q-brushes", "q-triangles"})
        for (int c = 0; c < 3; ++c, ++group)
            add_cell(frames, "tree", scene, group, rng.log_uniform(50, 2000), rng.log_uniform(50, 2000), kPrep, 0.02,
                     rng);
    return frames;
}

TEST(NestedValidation, ATwinIsNeverInTheFitThatPredictsItsTwinInEitherLoop) {
    const std::vector<FrameObservation> frames = twin_run();
    const std::vector<std::pair<std::string, std::string>> twins{
        {"m-brushes", "m-triangles"}, {"gen-2000", "gen-center-2000"}, {"q-brushes", "q-triangles"}};
    // Outer: every split holds both twins out or neither.
    std::vector<ValidationSplit> splits = family_out_splits(frames);
    EXPECT_EQ(splits.size(), 5u);  // m, gen-2000, other, gen-40000, q
    for (const ValidationSplit& s : nested_splits(frames)) {
        if (s.group.rfind("ray modes", 0) == 0) continue;  // transfers rays on known objects, by design
        std::set<std::string> test;
        for (std::size_t i : s.test) test.insert(frames[i].scene);
        for (const auto& [a, b] : twins) EXPECT_EQ(test.count(a), test.count(b)) << s.name << ": " << a;
    }
    // Inner: every candidate's k-fold puts the twins' rows in one fold, in each outer split's fit
    // as in the fit on everything.
    const auto check_inner = [&](const std::vector<const FrameObservation*>& fitted) {
        for (const StructureModels& m : fit_cost_models([&] {
                 std::vector<FrameObservation> v;
                 for (const FrameObservation* f : fitted) v.push_back(*f);
                 return v;
             }()))
            for (const auto* list : {&m.raycast, &m.update})
                for (const CandidateModel& c : *list) {
                    const std::vector<int> fold = fold_of_rows(c.problem);
                    ASSERT_EQ(fold.size(), fitted.size()) << c.name;  // a row per frame, in order
                    std::map<std::string, std::set<int>> folds_of;
                    for (std::size_t i = 0; i < fold.size(); ++i) folds_of[fitted[i]->scene].insert(fold[i]);
                    for (const auto& [a, b] : twins) {
                        if (!folds_of.count(a) || !folds_of.count(b)) continue;
                        EXPECT_EQ(folds_of[a].size(), 1u) << c.name;
                        EXPECT_EQ(folds_of[a], folds_of[b]) << c.name << ": " << a << " and " << b;
                    }
                }
    };
    std::vector<const FrameObservation*> all;
    for (const FrameObservation& f : frames) all.push_back(&f);
    check_inner(all);
    for (const ValidationSplit& s : splits) {
        std::vector<const FrameObservation*> train;
        for (std::size_t i : s.train) train.push_back(&frames[i]);
        check_inner(train);
    }
}

TEST(NestedValidation, TheInnerFoldsDealFamiliesNotCells) {
    // Six configurations in three families: with k = 5 there are three folds, one per family.
    LinearProblem p;
    p.terms = {"a"};
    for (int row = 0; row < 12; ++row) {
        p.x.push_back({1.0 + row});
        p.y.push_back(2.0 + 2 * row);
        p.group.push_back(row / 2);
        p.family.push_back(row / 4);
    }
    const std::vector<int> fold = fold_of_rows(p);
    for (int row = 0; row < 12; ++row) EXPECT_EQ(fold[std::size_t(row)], row / 4) << row;
    p.family.assign(12, 7);  // one family: nothing to hold out
    EXPECT_TRUE(std::isnan(cross_validated_error(p)));
    p.family.clear();  // without families, each configuration is its own
    EXPECT_NEAR(cross_validated_error(p), 0.0, 1e-6);
}

TEST(ValidationSummary, AnUnpredictableCellRaisesTheReportedErrorAndIsCounted) {
    std::vector<CellPrediction> cells;
    for (int s = 0; s < 4; ++s) {
        CellPrediction p;
        p.structure = "tree", p.scene = "s" + std::to_string(s), p.split = p.scene;
        p.frame_ns = 100, p.predicted_frame_ns = 100 * (1 + 0.01 * (s + 1));
        p.frame_error = 0.01 * (s + 1);
        cells.push_back(p);
    }
    const StructureValidation before = summarize(cells, {0, 1}).at(0);
    EXPECT_EQ(before.misses, 0u);
    CellPrediction unpriced;
    unpriced.structure = "tree", unpriced.scene = "s4", unpriced.split = "s4", unpriced.frame_ns = 100;
    ASSERT_FALSE(unpriced.predictable());
    cells.push_back(unpriced);
    const StructureValidation after = summarize(cells, {200, 1}).at(0);
    EXPECT_EQ(after.unpredictable, 1u);
    EXPECT_EQ(after.misses, 1u);
    EXPECT_GT(after.frame.median, before.frame.median);  // 0.03 of five cells, not 0.025 of four
    EXPECT_NEAR(after.frame.median, 0.03, 1e-12);
    EXPECT_TRUE(std::isinf(after.frame.p90));  // the p90 falls on the miss
    EXPECT_FALSE(std::isnan(after.frame.p90_low));
    EXPECT_DOUBLE_EQ(quantile({1, 2, INFINITY}, 0.5), 2);  // never inf − inf or 0·inf
    EXPECT_TRUE(std::isinf(quantile({1, INFINITY, INFINITY}, 0.9)));
}

/// A results database with one run of `frames` (their scenes, configurations and counters), as
/// `rcbench run` stores them.
void write_run(const std::string& path, const std::vector<FrameObservation>& frames, const std::string& uuid,
               int version = latest_schema_version(), const std::string& scenes = "") {
    const std::string hash = scenes.empty() ? uuid : scenes;  // the scenes' content, by hash
    ResultStore store(path, version);
    Database& db = store.db();
    db.exec("INSERT OR IGNORE INTO experiment(name) VALUES ('synthetic')");
    db.prepare(
          "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, "
          "compiler, flags, cpu_model, cores, governor, hostname, threads, shard) VALUES (?, 1, 'h', '{}', 't', 'g', "
          "'c', 'f', 'cpu', 1, 'gov', 'host', 1, '')")
        .bind(1, uuid)
        .run();
    const std::int64_t run = db.last_insert_id();
    std::map<int, std::int64_t> cells;
    for (const FrameObservation& f : frames) {
        if (!cells.count(f.config_group)) {
            const std::string spec =
                nlohmann::json{{"kind", f.category}, {"ray_mix", f.ray_mix}, {"objects", f.objects}}.dump();
            db.prepare(
                  "INSERT OR IGNORE INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) "
                  "VALUES (?, ?, ?, '{}', ?, 8, 1000, '{}')")
                .bind_all(hash + f.scene, f.scene, spec, std::int64_t(f.objects))
                .run();
            db.prepare("INSERT OR IGNORE INTO config(structure, params) VALUES (?, ?)")
                .bind_all(f.structure, "{\"g\":" + std::to_string(f.config_group) + "}")
                .run();
            db.prepare(
                  "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, "
                  "build_ns, memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, "
                  "raycast_ns_median, raycast_ns_mad) VALUES (?, ?, (SELECT id FROM scene WHERE hash = ?), "
                  "(SELECT id FROM config WHERE structure = ? AND params = ?), 0, 't', ?, 1, 0, 0, 0, 8, 0, 0, 0, 0)")
                .bind_all(run, std::to_string(f.config_group), hash + f.scene, f.structure,
                          "{\"g\":" + std::to_string(f.config_group) + "}", std::int64_t(f.objects))
                .run();
            cells[f.config_group] = db.last_insert_id();
        }
        const std::int64_t cell = cells[f.config_group];
        Statement n = db.prepare("SELECT count(*) FROM frame WHERE cell_id = ?");
        n.bind(1, cell);
        n.step();
        db.prepare(
              "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, "
              "missed, extra, duplicate, n_t, n_rb, n_tp, memory_bytes, stats) VALUES (?, ?, 0, 0, 0, ?, ?, ?, ?, 0, "
              "0, 0, 0, ?, ?, 0, 0, '{}')")
            .bind_all(cell, n.int64(0) + 1, std::int64_t(f.moves), std::int64_t(f.rays), std::int64_t(f.update_ns),
                      std::int64_t(f.raycast_ns), std::int64_t(std::llround(f.n_t * f.rays)),
                      std::int64_t(std::llround(f.n_rb * f.rays)))
            .run();
    }
}

::test::Outcome rcbench(std::vector<std::string> args) {
    args.insert(args.begin(), RCBENCH_BINARY);
    return ::test::run_process(args);
}

std::int64_t count(const std::string& path, const std::string& sql) {
    Database db(path, true);
    Statement s = db.prepare(sql);
    s.step();
    return s.int64(0);
}

TEST(ValidateCommand, StoresTransferInTheTestDatabaseAndNestedInTheTrainOne) {
    const test::TempDir dir("validation");
    const std::string a = dir.file("a.db"), b = dir.file("b.db");
    write_run(a, known_run(5, 4, 2, 50, 2000, 0.02), "ua");
    write_run(b, known_run(6, 3, 2, 100, 5000, 0.02), "ub");

    const ::test::Outcome t = rcbench({"validate", "--train", a + ":1", "--test", b, "--json", "--resamples", "50"});
    ASSERT_EQ(t.code, 0) << t.err;
    const nlohmann::json j = nlohmann::json::parse(t.out);
    EXPECT_EQ(j["bootstrap"]["seed"], 1);
    ASSERT_EQ(j["groups"].size(), 2u);
    EXPECT_EQ(j["groups"][0]["group"], "transfer");
    EXPECT_EQ(j["groups"][1]["group"], "calibration-only");  // these runs have no calibration: unpredictable
    EXPECT_LT(j["groups"][0]["structures"][0]["raycast_error"]["median"].get<double>(), 0.03);
    EXPECT_EQ(count(b, "SELECT count(*) FROM model_validation WHERE train_run_uuid = 'ua' AND seed = 1"), 1);
    EXPECT_EQ(count(b, "SELECT resamples FROM model_validation"), 50);
    // The cells priced beyond the train run's range are stored as printed.
    EXPECT_EQ(count(b, "SELECT outside_range FROM model_validation WHERE split = 'transfer'"),
              j["groups"][0]["structures"][0]["outside_range_cells"].get<std::int64_t>());
    // Stored again: replaced, not added; the file still passes the schema check of every reader.
    ASSERT_EQ(rcbench({"validate", "--train", a, "--test", b + ":1"}).code, 0);
    EXPECT_EQ(count(b, "SELECT count(*) FROM model_validation"), 2);  // the transfer and calibration alone
    EXPECT_EQ(count(a, "SELECT count(*) FROM model_validation"), 0);  // a transfer is stored in the test run's file
    EXPECT_NO_THROW(open_read_only(b));

    const ::test::Outcome n = rcbench({"validate", "--train", a, "--resamples", "20"});
    ASSERT_EQ(n.code, 0) << n.err;
    EXPECT_NE(n.out.find("leave-one-family-out (4 splits)"), std::string::npos) << n.out;
    EXPECT_EQ(count(a,
                    "SELECT count(*) FROM model_validation WHERE train = 'nested' AND split = "
                    "'leave-one-family-out' AND train_run_uuid = 'ua'"),
              1);
}

TEST(ValidateCommand, RepeatPrintsTheHeldOutErrorBesideTheSpreadBetweenRuns) {
    const test::TempDir dir("validation");
    const std::string a = dir.file("a.db"), b = dir.file("b.db");
    // The same scenes and configurations measured twice, with other noise.
    write_run(a, known_run(5, 4, 2, 50, 2000, 0.02), "ua", latest_schema_version(), "same");
    std::vector<FrameObservation> again = known_run(5, 4, 2, 50, 2000, 0.02);
    for (FrameObservation& f : again) f.raycast_ns *= 1.1, f.update_ns *= 1.1;  // every cell 10% slower
    write_run(b, again, "ub", latest_schema_version(), "same");
    const ::test::Outcome r = rcbench({"validate", "--train", a, "--repeat", b, "--resamples", "20"});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("leave-one-family-out beside the spread between run 1 and the repeat " + b), std::string::npos)
        << r.out;
    // tree: its frame error, the runs' spread of about 10% at the median, and the cells both hold.
    // The spread table's row is the last line that starts with the structure.
    std::vector<std::string> row;
    std::istringstream lines(r.out);
    for (std::string line; std::getline(lines, line);) {
        std::istringstream in(line);
        std::vector<std::string> words;
        for (std::string w; in >> w;) words.push_back(w);
        if (!words.empty() && words[0] == "tree") row = words;
    }
    ASSERT_EQ(row.size(), 8u) << r.out;
    EXPECT_EQ(row[2], "9.5%");  // (1.1 − 1) / 1.05: the relative range of two figures
    EXPECT_EQ(row.back(), "8");
    const ::test::Outcome j = rcbench({"validate", "--train", a, "--repeat", b, "--json", "--resamples", "20"});
    ASSERT_EQ(j.code, 0) << j.err;
    const nlohmann::json parsed = nlohmann::json::parse(j.out);
    ASSERT_EQ(parsed["between_runs"].size(), 1u);
    EXPECT_NEAR(parsed["between_runs"][0]["frame_median"].get<double>(), 0.1 / 1.05, 1e-3);
    // A bad --repeat names itself and stores nothing.
    const ::test::Outcome bad = rcbench({"validate", "--train", a, "--repeat", a + ":9"});
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.err.find("--repeat " + a + ":9: no run 9 in " + a), std::string::npos) << bad.err;
}

TEST(ValidateCommand, AnOlderDatabaseIsMigratedAndGainsTheTable) {
    const test::TempDir dir("validation");
    const std::string old = dir.file("old.db");
    write_run(old, known_run(5, 3, 2, 50, 2000, 0.02), "uo", 6);
    EXPECT_EQ(count(old, "PRAGMA user_version"), 6);
    const ::test::Outcome r = rcbench({"validate", "--train", old, "--resamples", "10"});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(count(old, "PRAGMA user_version"), latest_schema_version());
    EXPECT_EQ(count(old, "SELECT count(*) FROM model_validation WHERE split = 'leave-one-family-out'"), 1);
    EXPECT_NO_THROW(open_read_only(old));
    EXPECT_NO_THROW(ResultStore{old});  // the writers' schema check accepts it too
}

TEST(ValidateCommand, RunsThatMetDifferentCachesAreNoted) {
    const test::TempDir dir("validation");
    const std::string a = dir.file("a.db"), b = dir.file("b.db");
    write_run(a, known_run(5, 2, 2, 50, 2000, 0.02), "ua");
    write_run(b, known_run(5, 2, 2, 50, 2000, 0.02), "ub");
    const std::string note = "with a warm cache and " + b + ":1 with a cold one";
    EXPECT_EQ(rcbench({"validate", "--train", a, "--test", b, "--resamples", "10"}).err.find("note:"),
              std::string::npos);
    ResultStore(b).db().exec(R"(UPDATE run SET experiment_content = '{"cache": "cold"}')");
    for (const std::vector<std::string>& argv : std::vector<std::vector<std::string>>{
             {"validate", "--train", a, "--test", b, "--resamples", "10"}, {"fit", a, "--repeat", b}}) {
        const ::test::Outcome r = rcbench(argv);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_NE(r.err.find(note), std::string::npos) << argv[0] << ": " << r.err;
    }
    // fit --repeat gives the update's agreement band by band of its size, every band named.
    const std::string out = rcbench({"fit", a, "--repeat", b}).out;
    for (const char* band : {"under 10 us", "10-30 us", "30-100 us", "100 us and over"})
        EXPECT_NE(out.find(band), std::string::npos) << band << "\n" << out;
}

TEST(ValidateCommand, BadInputNamesTheOptionAndExitsTwo) {
    const test::TempDir dir("validation");
    const std::string a = dir.file("a.db"), empty = dir.file("empty.db");
    write_run(a, known_run(5, 2, 2, 50, 2000, 0.02), "ua");
    write_run(empty, {}, "ue");  // a run without cells
    const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
        {{"--train", dir.file("absent.db")}, "--train " + dir.file("absent.db") + ": no such results database"},
        {{"--train", a + ":7"}, "--train " + a + ":7: no run 7 in " + a},
        {{"--train", a + ":0"}, "--train " + a + ":0: a run id is a whole number >= 1"},
        {{"--train", empty + ":1"}, "--train " + empty + ":1: run 1 has no measured frames"},
        {{"--train", empty}, "--train " + empty + ": " + empty + ": the database has no measured run"},
        {{"--train", a, "--test", dir.file("absent.db")}, "--test " + dir.file("absent.db") + ": no such"},
        {{"--train", a, "--test", empty + ":1"}, "--test " + empty + ":1: run 1 has no measured frames"},
        {{"--train", a, "--resamples", "0"}, "--resamples"},
        {{}, "--train is required"},
    };
    for (const auto& [args, message] : cases) {
        std::vector<std::string> argv{"validate"};
        argv.insert(argv.end(), args.begin(), args.end());
        const ::test::Outcome r = rcbench(argv);
        EXPECT_EQ(r.code, 2) << message << "\n" << r.err;
        EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
    // fit --repeat: the other run is checked before the fit stores anything in the database.
    const std::vector<std::pair<std::vector<std::string>, std::string>> repeat_cases{
        {{a, "--repeat", dir.file("absent.db")}, "--repeat " + dir.file("absent.db") + ": no such results database"},
        {{a, "--repeat", a + ":7"}, "--repeat " + a + ":7: no run 7 in " + a},
        {{a, "--repeat", a + ":0"}, "--repeat " + a + ":0: a run id is a whole number >= 1"},
    };
    const auto bytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), {});
    };
    const std::string before = bytes(a);
    for (const auto& [args, message] : repeat_cases) {
        std::vector<std::string> argv{"fit"};
        argv.insert(argv.end(), args.begin(), args.end());
        const ::test::Outcome r = rcbench(argv);
        EXPECT_EQ(r.code, 2) << message << "\n" << r.err;
        EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_EQ(bytes(a), before) << message;
    }
    const ::test::Outcome help = rcbench({"validate", "--help"});
    EXPECT_EQ(help.code, 0);
    for (const char* option : {"--train", "--test", "--repeat", "--json", "--resamples", "--seed"})
        EXPECT_NE(help.out.find(option), std::string::npos) << option;
}

}  // namespace
}  // namespace rcb

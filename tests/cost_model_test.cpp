// The cost model's identifiability and validation: collinear counters (a BVH's N_RB and N_T move
// together) are told apart only with calibration priors and reported as not identifiable without
// them; leave-one-family-out never fits a scene family it then predicts; the memory tiers follow
// the caches.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <tuple>

#include "analysis/cost_model.h"
#include "analysis/linear_fit.h"
#include "core/base/random.h"

namespace rcb {
namespace {

constexpr double kRb = 2.0, kT = 4.0, kPrep = 30.0;

/// Frames of one structure whose N_T is twice N_RB (to 0.1%): the counters of a BVH, collinear.
std::vector<FrameObservation> collinear_frames(std::uint64_t seed, int scenes = 8, int configs_per_scene = 2) {
    Random rng(seed);
    std::vector<FrameObservation> frames;
    int group = 0;
    for (int s = 0; s < scenes; ++s)
        for (int c = 0; c < configs_per_scene; ++c, ++group) {
            const double n_rb = rng.log_uniform(20, 2000);
            for (int f = 0; f < 10; ++f) {
                FrameObservation o;
                o.structure = "tree";
                o.scene = "scene" + std::to_string(s);
                o.category = "irregular";
                o.params = "{\"c\":" + std::to_string(c) + "}";
                o.config_group = group;
                o.rays = 1000;
                o.n_rb = n_rb * (1 + 0.02 * rng.normal());
                o.n_t = 2 * o.n_rb * (1 + 0.001 * rng.normal());
                o.n_tp = 0.1 * o.n_rb;
                o.raycast_ns = o.rays * (kRb * o.n_rb + kT * o.n_t + kPrep) * (1 + 0.02 * rng.normal());
                o.moves = 100 + 10 * s;
                o.update_ns = 500 * o.moves + 2000;
                frames.push_back(o);
            }
        }
    return frames;
}

/// What the calibration pass measures: micro-scenes whose counters vary independently.
std::vector<CalibrationPoint> calibration_points(double scale_rb, double scale_t, std::uint64_t seed) {
    Random rng(seed);
    const double design[][2] = {{0, 1}, {0, 40}, {12, 60}, {0, 20}, {256, 1}, {20, 120}, {0, 15}, {256, 10}};
    std::vector<CalibrationPoint> out;
    for (const auto& d : design)
        out.push_back({"micro", 512, d[0], d[1],
                       (scale_rb * kRb * d[0] + scale_t * kT * d[1] + kPrep) * (1 + 0.01 * rng.normal()), 0.1});
    return out;
}

TEST(Identifiability, LinesFetchedOnTheLargeLatticeGoToCMissOrAreLeftOut) {
    // The small scenes at the true in-cache costs; the two on the large lattice also fetch lines at
    // 25 ns each. Counted, they pin C_MISS; not counted (a structure that cannot count them), they
    // are left out rather than charged to C_RB and C_T.
    std::vector<CalibrationPoint> points = calibration_points(1, 1, 5);
    for (std::size_t i = 0; i < points.size(); ++i) points[i].scene = "micro-" + std::to_string(i);
    for (const auto& [scene, rb, t, miss] : {std::tuple{"scatter-32", 2.0, 45.0, 9.0}, {"short-32", 0.5, 24.0, 4.5}})
        points.push_back({scene, 512, rb, t, kRb * rb + kT * t + kPrep + 25.0 * miss, 0.1, 0, miss});
    const StructureCalibration counted = fit_calibration("tree", points);
    EXPECT_EQ(counted.points.size(), points.size());
    ASSERT_NE(counted.term("C_MISS"), nullptr);
    EXPECT_NEAR(counted.term("C_MISS")->value, 25.0, 2.5);
    for (CalibrationPoint& p : points) p.n_miss = 0;
    const StructureCalibration uncounted = fit_calibration("peer", points);
    EXPECT_EQ(uncounted.points.size(), points.size() - 2);
    EXPECT_EQ(uncounted.term("C_MISS"), nullptr);
    ASSERT_NE(uncounted.term("C_T"), nullptr);
    EXPECT_NEAR(uncounted.term("C_T")->value, kT, 0.05 * kT);
}

TEST(Identifiability, HitsPricedApartFromTestsWhereTheMicroScenesSeparateThem) {
    // Tests at kRb, each reported hit 1.2 ns more. With every test a hit on the stack and few in
    // the cluster, the fit pins both; without C_HIT it would charge the stack's hits to C_RB.
    constexpr double kHit = 1.2;
    std::vector<CalibrationPoint> points = calibration_points(1, 1, 7);
    const double hits[] = {0, 0, 12, 0, 256, 2, 0, 256};
    for (std::size_t i = 0; i < points.size(); ++i) {
        points[i].n_tp = hits[i];
        points[i].ns_per_ray += kHit * hits[i];
    }
    CalibrationPoint cluster{"cluster", 512, 90, 12, kRb * 90 + kT * 12 + kPrep + kHit * 0.4, 0.1};
    cluster.n_tp = 0.4;
    points.push_back(cluster);
    const StructureCalibration c = fit_calibration("grid", points);
    ASSERT_NE(c.term("C_HIT"), nullptr);
    EXPECT_NEAR(c.term("C_HIT")->value, kHit, 0.15 * kHit);
    EXPECT_NEAR(c.term("C_RB")->value, kRb, 0.15 * kRb);
    EXPECT_TRUE(c.term("C_RB")->pinned);

    EXPECT_EQ(c.points.size(), points.size());

    // A peer names its hits as its candidates: N_TP equals N_RB, so C_HIT cannot be priced apart
    // and the calibration is fitted as before C_HIT, without the cluster.
    for (CalibrationPoint& p : points) p.n_tp = p.n_rb;
    const StructureCalibration peer = fit_calibration("peer", points);
    EXPECT_EQ(peer.term("C_HIT"), nullptr);
    EXPECT_EQ(peer.points.size(), points.size() - 1);
    ASSERT_NE(peer.term("C_RB"), nullptr);
    EXPECT_TRUE(peer.term("C_RB")->pinned) << peer.term("C_RB")->why;
}

TEST(Identifiability, CollinearCountersAreReportedWithoutPriors) {
    const std::vector<FrameObservation> frames = collinear_frames(1);
    LinearProblem p;
    p.terms = {"C_RB", "C_T", "C_PREP"};
    for (const FrameObservation& f : frames) {
        p.x.push_back({f.n_rb, f.n_t, 1.0});
        p.y.push_back(f.raycast_ns / f.rays);
        p.group.push_back(f.config_group);
    }
    const LinearFit fit = fit_linear(p);
    EXPECT_TRUE(fit.ill_conditioned);
    EXPECT_EQ(fit.status(), "ill-conditioned (collinear terms)");

    // The cost model without a calibration: no chosen model claims both terms as estimates.
    const std::vector<StructureModels> models = fit_cost_models(frames);
    const CandidateModel* m = models.at(0).chosen("raycast");
    ASSERT_NE(m, nullptr);
    const bool both = std::count(m->problem.terms.begin(), m->problem.terms.end(), "C_RB") &&
                      std::count(m->problem.terms.begin(), m->problem.terms.end(), "C_T");
    EXPECT_TRUE(!both || m->fit.status() != "ok");
    if (!both) {  // one of them was dropped, and the model says why
        ASSERT_FALSE(m->dropped.empty());
        EXPECT_NE(m->dropped.front().find("no calibration value (the run has no calibration)"), std::string::npos)
            << m->dropped.front();
    }
}

TEST(Identifiability, CalibrationPriorsRecoverCollinearCoefficients) {
    const std::vector<FrameObservation> frames = collinear_frames(2);
    // Priors off by +10% and −10%: the data fix C_RB + 2·C_T, the priors split it.
    LinearProblem p;
    p.terms = {"C_RB", "C_T", "C_PREP"};
    p.prior = {1.1 * kRb, 0.9 * kT, kPrep};
    for (const FrameObservation& f : frames) {
        p.x.push_back({f.n_rb, f.n_t, 1.0});
        p.y.push_back(f.raycast_ns / f.rays);
        p.group.push_back(f.config_group);
    }
    const LinearFit fit = fit_linear(p);
    EXPECT_EQ(fit.status(), "ok");
    EXPECT_NEAR(fit.coefficients[0].value, kRb, 0.15 * kRb);
    EXPECT_NEAR(fit.coefficients[1].value, kT, 0.15 * kT);
    EXPECT_NEAR(fit.coefficients[0].value + 2 * fit.coefficients[1].value, kRb + 2 * kT, 0.03 * (kRb + 2 * kT));

    // End to end: the calibration (micro-scenes measured at the true costs) pins the terms and the
    // chosen model recovers them, positive and within 3× of the calibration.
    ModelInputs inputs;
    inputs.calibrations.push_back(fit_calibration("tree", calibration_points(1.0, 1.0, 3)));
    for (const CalibratedTerm& t : inputs.calibrations[0].terms) EXPECT_TRUE(t.pinned) << t.name << ": " << t.why;
    const std::vector<StructureModels> models = fit_cost_models(frames, inputs);
    const CandidateModel* m = models.at(0).chosen("raycast");
    ASSERT_NE(m, nullptr);
    EXPECT_EQ(m->fit.status(), "ok");
    const double truth[] = {kRb, kT, kPrep};
    const char* names[] = {"C_RB", "C_T", "C_PREP"};
    for (int j = 0; j < 3; ++j) {
        const auto it = std::find_if(m->fit.coefficients.begin(), m->fit.coefficients.end(),
                                     [&](const Coefficient& c) { return c.name == names[j]; });
        ASSERT_NE(it, m->fit.coefficients.end()) << names[j];
        EXPECT_NEAR(it->value, truth[j], 0.1 * truth[j]) << names[j];
        EXPECT_GT(it->value, 0);
        EXPECT_LE(it->value, kPriorRange * it->prior * (1 + 1e-9));
        EXPECT_GE(it->value, it->prior / kPriorRange * (1 - 1e-9));
    }
}

TEST(Identifiability, PriorsBoundCoefficientsToThreeTimesTheCalibration) {
    // 500 frames say C_RB = 2; a calibration of 0.5 allows at most 1.5, and the fit says it hit the
    // bound (with 500 frames the data outweigh the prior's pull).
    LinearProblem p;
    p.terms = {"C_RB"};
    p.prior = {0.5};
    for (int i = 1; i <= 500; ++i) {
        p.x.push_back({double(10 + i)});
        p.y.push_back(2.0 * (10 + i));
        p.group.push_back(i % 25);
    }
    const LinearFit fit = fit_linear(p);
    EXPECT_NEAR(fit.coefficients[0].value, 1.5, 1e-6);
    EXPECT_TRUE(fit.coefficients[0].at_bound);
}

TEST(Identifiability, UnpinnedCalibrationTermsSayWhy) {
    // A structure whose micro-scenes never vary N_T independently of start-up cannot pin C_T.
    std::vector<CalibrationPoint> points;
    for (int i = 0; i < 6; ++i) points.push_back({"micro", 512, double(10 * i), 1.0, 3.0 * 10 * i + 20 + 0.01 * i, 0});
    const StructureCalibration c = fit_calibration("s", points);
    ASSERT_NE(c.term("C_T"), nullptr);
    EXPECT_FALSE(c.term("C_T")->pinned);
    EXPECT_FALSE(c.term("C_T")->why.empty());
}

TEST(LeaveOneSceneOut, SplitsNeverLeakASceneIntoItsOwnFit) {
    const std::vector<FrameObservation> frames = collinear_frames(4, 5, 3);
    std::vector<const FrameObservation*> ptrs;
    for (const FrameObservation& f : frames) ptrs.push_back(&f);
    const std::vector<SceneSplit> splits = scene_splits(ptrs);
    ASSERT_EQ(splits.size(), 5u);
    for (const SceneSplit& s : splits) {
        EXPECT_EQ(s.train.size() + s.test.size(), frames.size());
        EXPECT_FALSE(s.test.empty());
        for (std::size_t i : s.train) EXPECT_NE(frames[i].scene, s.scene);
        for (std::size_t i : s.test) EXPECT_EQ(frames[i].scene, s.scene);
    }
}

TEST(LeaveOneSceneOut, AScenePredictedOnlyFromTheOthers) {
    ModelInputs inputs;
    inputs.calibrations.push_back(fit_calibration("tree", calibration_points(1.0, 1.0, 5)));
    std::vector<FrameObservation> frames = collinear_frames(6, 6, 2);
    // One scene costs 3× what the others predict: held out, it is predicted at about a third of its
    // time (error 2/3). Were its own frames in the fit, they would pull the prediction towards them.
    for (FrameObservation& f : frames)
        if (f.scene == "scene3") f.raycast_ns *= 3, f.update_ns *= 3;
    const std::vector<StructureModels> models = fit_cost_models(frames, inputs);
    const StructureModels& m = models.at(0);
    ASSERT_EQ(m.loso.size(), 6u);
    for (const SceneError& e : m.loso) {
        ASSERT_TRUE(std::isfinite(e.frame_error)) << e.scene;
        if (e.scene == "scene3")
            EXPECT_NEAR(e.frame_error, 2.0 / 3.0, 0.05);
        else
            EXPECT_LT(e.frame_error, 0.6) << e.scene;
    }

    // A structure measured on one scene only has nothing to be predicted from.
    std::vector<FrameObservation> one;
    for (const FrameObservation& f : frames)
        if (f.scene == "scene0") one.push_back(f);
    const std::vector<StructureModels> single = fit_cost_models(one, inputs);
    ASSERT_EQ(single.at(0).loso.size(), 1u);
    EXPECT_TRUE(std::isnan(single.at(0).loso[0].frame_error));
    EXPECT_TRUE(std::isnan(single.at(0).loso_error));
}

TEST(MemoryHierarchy, TiersFollowTheCaches) {
    const std::vector<CacheLevel> caches{{1, "Data", 48 << 10}, {2, "Unified", 2 << 20}, {3, "Unified", 32 << 20}};
    EXPECT_EQ(memory_tier_of(16 << 10, caches), 0);
    EXPECT_EQ(memory_tier_of(1 << 20, caches), 1);
    EXPECT_EQ(memory_tier_of(8 << 20, caches), 2);
    EXPECT_EQ(memory_tier_of(100 << 20, caches), 3);
    EXPECT_EQ(memory_tier_of(100 << 20, {}), 0);
}

/// Update frames of one structure per scene: `mixes[s]` is scene s's share of inserts, removes and
/// moves; an insert costs 1000 ns, a remove 100, a move 400, plus 2 µs a frame.
std::vector<FrameObservation> update_frames(const std::vector<std::array<double, 3>>& mixes, std::uint64_t seed) {
    Random rng(seed);
    std::vector<FrameObservation> frames;
    for (std::size_t s = 0; s < mixes.size(); ++s) {
        const double changes = 100.0 * double(s + 1);
        for (int f = 0; f < 10; ++f) {
            FrameObservation o;
            o.structure = "grid";
            o.scene = "scene" + std::to_string(s);
            o.config_group = int(s);
            o.inserts = std::round(changes * mixes[s][0]);
            o.removes = std::round(changes * mixes[s][1]);
            o.moves = std::round(changes * mixes[s][2]);
            o.update_ns = (1000 * o.inserts + 100 * o.removes + 400 * o.moves + 2000) * (1 + 0.01 * rng.normal());
            frames.push_back(o);
        }
    }
    return frames;
}

TEST(ModelSelection, ACellBeyondTheFittedRangeIsNamed) {
    // Fitted on 100 to 600 changes per frame: 1000 is within twice that, 10000 is not, and the
    // counter is named with the value and the range.
    const std::array<double, 3> usual{0.1, 0.1, 0.8};
    const std::vector<StructureModels> models =
        fit_cost_models(update_frames({usual, usual, usual, usual, usual, usual}, 5));
    const StructureModels& m = models.at(0);
    std::vector<FrameObservation> frames = update_frames({usual}, 6);
    std::vector<const FrameObservation*> cell;
    for (FrameObservation& f : frames) {
        f.moves = 800;
        cell.push_back(&f);
    }
    EXPECT_EQ(outside_trained_range(m, cell), "");
    for (FrameObservation& f : frames) f.moves = 9980;
    EXPECT_EQ(outside_trained_range(m, cell), "changes per frame 10000 (fitted on 100–600)");
}

TEST(ModelSelection, HitsPerRayBeyondTheFittedRangeAreNamedWhereAHitIsPriced) {
    // A model that prices a reported hit (C_HIT) extrapolates on a cell with twice the hits per ray
    // of its fit (a dense mesh's dozens of small triangles in one cell); one that does not has the
    // hits among its box tests, where N_RB's range speaks for them.
    StructureModels m;
    m.trained = {{"N_TP per ray", 1.0, 10.0}};
    CandidateModel ray;
    ray.target = "raycast";
    ray.chosen = true;
    ray.problem.terms = {"C_RB", "C_T", "C_PREP"};
    m.raycast.push_back(ray);
    FrameObservation f;
    f.rays = 1000;
    f.n_tp = 27;
    const std::vector<const FrameObservation*> cell{&f};
    EXPECT_EQ(outside_trained_range(m, cell), "");
    m.raycast[0].problem.terms.push_back("C_HIT");
    EXPECT_EQ(outside_trained_range(m, cell), "N_TP per ray 27.0 (fitted on 1.00–10.0)");
    f.n_tp = 15;
    EXPECT_EQ(outside_trained_range(m, cell), "");
}

}  // namespace
}  // namespace rcb

// The tuner: the NLopt search against exhaustive search on a known cost surface, seed stability,
// enumeration of small spaces, edge reporting, the simplicity rule, tuning files, a real tuning, and
// what a tuning records for advise (its spaces and cost models).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "analysis/linear_fit.h"
#include "core/base/error.h"
#include "core/base/json_input.h"
#include "core/base/number_text.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "tests/test_scenes.h"
#include "tests/test_timing.h"
#include "tuner/run_tuning.h"
#include "tuner/search.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// A 6 × 5 × 4 × 2 = 240-point space shaped like grid tuning: a valley in (amp, depth), a weak
/// capacity effect, a flat choice, and 1% deterministic noise (no smoothness to exploit).
std::vector<SearchDimension> grid_like_space() {
    return {{"amp", {0.125, 0.25, 0.5, 1.0, 2.0, 4.0}},
            {"depth", {0, 1, 2, 3, 4}},
            {"capacity", {4, 8, 16, 32}},
            {"flag", {false, true}}};
}

double grid_like_cost(const json& p) {
    const double amp = std::log2(p["amp"].get<double>()), depth = p["depth"].get<double>();
    const double capacity = std::log2(p["capacity"].get<double>());
    double cost = 1.0 + 0.15 * (amp - 0.7) * (amp - 0.7) + 0.2 * std::abs(depth - 2.2) +
                  0.05 * std::abs(capacity - 3.4) + 0.1 * (amp - 0.7) * (depth - 2.2) / 4;
    const std::size_t h = std::hash<std::string>{}(p.dump());
    return cost * (1 + 0.01 * (double(h % 1000) / 1000.0 - 0.5));
}

TEST(TunerSearch, FindsWithinFivePercentOfTheExhaustiveOptimumWithAQuarterOfTheEvaluations) {
    const auto dims = grid_like_space();
    double optimum = INFINITY;
    const auto all = enumerate_space(dims);
    for (const json& p : all) optimum = std::min(optimum, grid_like_cost(p));
    const std::size_t budget = all.size() / 4;  // 60 of 240
    std::vector<double> found;
    for (std::uint64_t seed = 1; seed <= 5; ++seed) {
        std::size_t calls = 0;
        const SearchResult r = search_levels(
            dims, [&](const json& p) { return ++calls, grid_like_cost(p); }, budget, seed);
        EXPECT_LE(r.evaluations.size(), budget);
        EXPECT_EQ(calls, r.evaluations.size());  // memoised: every call is a distinct configuration
        const double best = r.evaluations[r.best].cost;
        EXPECT_LE(best, optimum * 1.05) << "seed " << seed;
        found.push_back(best);
    }
    // Across seeds the chosen configurations' costs differ by at most 5%.
    EXPECT_LE(*std::max_element(found.begin(), found.end()), 1.05 * *std::min_element(found.begin(), found.end()));
}

TEST(TunerSearch, EnumeratesASpaceNoLargerThanTheBudgetAndReportsEdges) {
    const std::vector<SearchDimension> dims{{"density", {0.5, 1.0, 2.0, 4.0}}};
    const SearchResult r = search_levels(
        dims, [](const json& p) { return p["density"].get<double>(); }, 10, 1);
    EXPECT_EQ(r.algorithm, "enumeration");
    EXPECT_EQ(r.evaluations.size(), 4u);
    EXPECT_EQ(r.evaluations[r.best].params["density"], 0.5);
    EXPECT_EQ(r.on_bound, std::vector<std::string>{"density"});  // the best is the smallest level: widen the range
}

TEST(TunerSearch, IntegerLevelsAreOnlyEverEvaluatedAtTheirValues) {
    const std::vector<SearchDimension> dims{{"depth", {0, 1, 2, 3, 4, 5, 6}},
                                            {"capacity", {1, 2, 4, 8, 16, 32, 64, 128, 256}}};
    const SearchResult r = search_levels(
        dims,
        [](const json& p) {
            EXPECT_TRUE(p["depth"].is_number_integer());
            EXPECT_TRUE(p["capacity"].is_number_integer());
            return std::abs(p["depth"].get<int>() - 3) + std::abs(std::log2(p["capacity"].get<double>()) - 4.0);
        },
        20, 3);
    EXPECT_EQ(r.evaluations[r.best].params["depth"], 3);
    EXPECT_EQ(r.evaluations[r.best].params["capacity"], 16);
    EXPECT_TRUE(r.on_bound.empty());
}

TEST(TunerRule, PrefersTheSimplestConfigurationWithinThreePercent) {
    auto candidate = [](const char* structure, double ms, double memory) {
        Candidate c;
        c.structure = structure;
        c.measured = MeasuredCost{ms, 0, 0, 0, memory, {}};
        return c;
    };
    const Candidate hg_fast = candidate("hg", 1.00, 2e6), ug_close = candidate("ug", 1.02, 3e6),
                    ug_far = candidate("ug", 1.10, 1e6);
    EXPECT_EQ(simplest_within({&hg_fast, &ug_close, &ug_far}, 0.03), 1u);  // UG within 3% beats a faster HG
    EXPECT_EQ(simplest_within({&hg_fast, &ug_far}, 0.03), 0u);             // 10% slower is not "close"
    const Candidate hg_small = candidate("hg", 1.01, 1e6);
    EXPECT_EQ(simplest_within({&hg_fast, &hg_small}, 0.03), 1u);  // same structure: less memory
}

std::string tune_error(const std::string& text) {
    return test::input_error_of([&] { parse_tune_spec(text, "t.json", "."); });
}

TEST(TuneSpec, ValidatesWithJsonPaths) {
    const char* ok = R"({"structures": ["ug"], "categories": [{"name": "u", "scenes": [{"preset": "uni-s"}]}]})";
    EXPECT_EQ(tune_error(ok), "");
    EXPECT_EQ(tune_error(R"({"mode": "fast", "categories": []})"),
              "t.json: mode: expected one of measured, predicted, predicted-then-verified, got \"fast\"");
    EXPECT_EQ(tune_error(R"({"structures": ["bf"], "categories": [{"name": "u", "scenes": [{"preset": "uni-s"}]}]})"),
              "t.json: structures: bf has no tunable parameter");
    EXPECT_EQ(
        tune_error(
            R"({"structures": ["ug"], "space": {"ug": {"density": [0.5, 100]}}, "categories": [{"name": "u", "scenes": [{"preset": "uni-s"}]}]})"),
        "t.json: space.ug.density[1]: expected a number in 0.1..64, got 100");
    EXPECT_EQ(tune_error(R"({"structures": ["ug"], "categories": [{"name": "u", "scenes": [{"preset": "uni-q"}]}]})")
                  .find("t.json: categories[0].scenes[0].preset: unknown preset 'uni-q'"),
              0u);
    EXPECT_EQ(
        tune_error(
            R"({"structures": ["ug"], "categories": [{"name": "u", "scenes": [{"preset": "uni-s"}]}, {"name": "u", "scenes": [{"preset": "uni-s"}]}]})"),
        "t.json: categories[1].name: duplicate category name \"u\"");
    // A number too large for a double is bad JSON, not a crash (as in experiment files).
    EXPECT_EQ(tune_error(R"({"budget": 1e999})").find("t.json: not valid JSON"), 0u);
    const TuneSpec spec = parse_tune_spec(ok, "t.json", ".");
    ASSERT_EQ(spec.space.at("ug").size(), 1u);  // density; thesis_reset is not tunable
    EXPECT_EQ(spec.space.at("ug")[0].name, "density");
    EXPECT_GE(spec.space.at("ug")[0].levels.size(), 8u);
}

TEST(TuneSpec, GeneratedLevelsAreCleanAndMeetTheDefault) {
    // A tuning's range through the default gives the default itself, so the search's level and the
    // defaults' candidate are one configuration (measured once), not 4.000000000000001 beside 4.0.
    const TuneSpec spec = parse_tune_spec(
        R"({"structures": ["ug"], "space": {"ug": {"density": {"from": 0.125, "to": 64, "times": 1.4142135623730951}}},
            "categories": [{"name": "c", "scenes": [{"preset": "uni-s"}]}]})",
        "t.json", ".");
    const std::vector<json>& levels = spec.space.at("ug")[0].levels;
    ASSERT_EQ(levels.size(), 19u);
    EXPECT_EQ(std::count(levels.begin(), levels.end(), find_structure("ug").defaults()["density"]), 1);
    // The registry's levels (default_space) of every real parameter: no float noise either.
    for (const StructureInfo& info : structure_registry())
        for (const SearchDimension& d : default_space(info.name))
            for (const json& level : d.levels) {
                if (!level.is_number_float()) continue;
                EXPECT_EQ(level.get<double>(), decimal_rounded(level.get<double>())) << info.name << "." << d.name;
            }
}

TEST(TuneSpec, AHugeSearchSpaceIsRefusedBeforeItIsEnumerated) {
    const std::string text = R"({"structures": ["hg"], "space": {"hg": {"amp": {"from": 0.01, "to": 16, "step": 0.002},
        "max_capacity": {"from": 1, "to": 256, "step": 1}, "max_depth": [0, 1, 2, 3, 4, 5, 6]}},
        "categories": [{"name": "c", "scenes": [{"preset": "uni-s"}]}]})";
    const std::string m = test::input_error_of([&] { parse_tune_spec(text, "t.json", "."); });
    EXPECT_EQ(m.rfind("t.json: space.hg: the search space has", 0), 0u) << m;
}

TEST(Tune, PredictedThenVerifiedMeasuresItsCandidatesAndTheDefaults) {
    TuneSpec spec = parse_tune_spec(
        R"({"structures": ["ug"], "budget": 5, "calibration": 4, "verify_top": 2, "frames": 3, "rays_per_frame": 200, "repetitions": 1,
            "space": {"ug": {"density": {"from": 0.25, "to": 16, "times": 2}}},
            "categories": [{"name": "small", "scenes": [{"generator": "irregular", "objects": 2000}]}]})",
        "t.json", ".");
    // Made-up times from the counters: how far the predicted search gets before it converges
    // depends on the predictions, which the replays' update times enter, and on a loaded machine
    // those would decide it.
    spec.categories[0].timing = test::counted_timing(2.0, 20.0, 50.0);
    const CategoryTuning t = tune_category(spec, spec.categories[0]);
    ASSERT_EQ(t.structures.size(), 1u);
    const StructureTuning& st = t.structures[0];
    EXPECT_LE(st.search.evaluations.size(), 5u);  // at most the budget of distinct predicted evaluations
    EXPECT_GE(st.search.evaluations.size(), 3u);
    EXPECT_TRUE(st.search.stop_reason == "budget" || st.search.stop_reason == "converged") << st.search.stop_reason;
    EXPECT_FALSE(st.prediction_model.empty());
    std::size_t defaults = 0, predicted = 0;
    for (const Candidate& c : st.candidates) {
        ASSERT_TRUE(c.measured.has_value());
        EXPECT_GT(c.measured->ms, 0);
        defaults += c.is_default;
        predicted += c.predicted_ms.has_value();
    }
    EXPECT_EQ(defaults, 1u);
    EXPECT_GE(predicted, 2u);  // the verified candidates carry both numbers
    EXPECT_LE(t.chosen.measured->ms, 1.03 * t.fastest.measured->ms);
}

TEST(Tune, TheDefaultsSpelledAsAnIntegerAreMeasuredOnce) {
    // ug's default density is 4.0; the space lists it as 4, the JSON integer.
    const TuneSpec spec = parse_tune_spec(
        R"({"structures": ["ug"], "budget": 8, "frames": 2, "rays_per_frame": 50, "repetitions": 1,
            "space": {"ug": {"density": [2, 4]}},
            "categories": [{"name": "small", "scenes": [{"generator": "uniform", "objects": 500}]}]})",
        "t.json", ".");
    const CategoryTuning t = tune_category(spec, spec.categories[0]);
    ASSERT_EQ(t.structures.size(), 1u);
    EXPECT_EQ(t.structures[0].candidates.size(), 2u);  // density 2 and density 4 (the defaults), not a third
}

TEST(TuneRecordsForAdvise, EveryModeRecordsItsSpaceAndACostModel) {
    namespace fs = std::filesystem;
    const test::TempDir temp("tuner", "records_for_advise");
    const fs::path& dir = temp.path();
    for (const char* mode : {"measured", "predicted-then-verified"}) {
        TuneSpec spec = parse_tune_spec(
            std::string(R"({"name": "rec", "structures": ["ug"], "budget": 4, "calibration": 4, "frames": 3,
                "rays_per_frame": 200, "repetitions": 1, "mode": ")") +
                mode + R"(", "space": {"ug": {"density": [0.5, 1, 2, 4, 8]}},
                "categories": [{"name": "u", "scenes": [{"generator": "uniform", "objects": 2000}]}]})",
            "rec.json", dir.string());
        // Frames timed by eq. 5.4 itself (C_RB 2, C_T 20, C_PREP 50 ns): the model fitted to timed
        // frames of five configurations decides this test's verdict, and timed by the clock of a
        // loaded machine it once priced memory alone. The fallbacks on noisy frames have tests of
        // their own (TuneCostModel below).
        spec.categories[0].timing = test::counted_timing(2.0, 20.0, 50.0);
        TuneOptions o;
        o.file = (dir / "rec.json").string();
        o.db = (dir / "t.db").string();
        o.out_dir = dir.string();
        const TuneOutcome out = run_tuning(spec, o);
        const json ug = json::parse(std::ifstream(out.json_path))["categories"][0]["structures"][0];
        // Each mode measured at least two configurations, the defaults at most once: the predicted
        // modes always, the measured mode's ranked method where the model ranks them in its budget.
        ASSERT_EQ(out.categories.size(), 1u);
        ASSERT_EQ(out.categories[0].structures.size(), 1u);
        const StructureTuning& st = out.categories[0].structures[0];
        EXPECT_GE(st.candidates.size(), 2u) << mode;
        const auto defaults =
            std::count_if(st.candidates.begin(), st.candidates.end(), [](const Candidate& c) { return c.is_default; });
        if (std::string(mode) == "measured")
            EXPECT_LE(defaults, 1) << mode;
        else
            EXPECT_EQ(defaults, 1) << mode;
        ASSERT_EQ(ug["space"].size(), 1u) << mode;
        EXPECT_EQ(ug["space"][0]["name"], "density");
        EXPECT_EQ(ug["space"][0]["levels"].size(), 5u);
        // The measured mode fits it to the frames its search measured (counted on the first
        // repetition), the predicted modes keep their calibration's.
        ASSERT_TRUE(ug.contains("cost_model")) << mode;
        // It prices the rays' work: tests, steps, or (where the few measured points cannot tell
        // the two kinds of step apart) the unpredicted steps alone.
        const json& m = ug["cost_model"];
        EXPECT_GT(m["C_T"].get<double>() + m["C_RB"].get<double>() + m["C_MP"].get<double>(), 0) << mode << m.dump();
        // Fitted to these frames alone, not the machine's calibration (which the measured mode's
        // ranking starts from).
        EXPECT_EQ(m["model"].get<std::string>().find("calibration"), std::string::npos) << mode << m.dump();
        // Beside it, the update's prices, read back as advise reads them: an untimed replay priced
        // by them predicts the update the frames were timed at (1 µs + 200 ns per change), and
        // times nothing.
        ASSERT_TRUE(ug.contains("update_model")) << mode;
        const UpdatePrices prices = UpdatePrices::from_json(ug["update_model"], "rec");
        EXPECT_FALSE(prices.terms.empty()) << mode;
        const std::uint64_t phases = timed_phases();
        const CountingReplay replay = counting_replay(spec.categories[0], "ug", json{{"density", 2}}, 1, &prices);
        EXPECT_EQ(timed_phases(), phases) << mode;
        EXPECT_FALSE(replay.update_timed);
        ASSERT_FALSE(replay.scenes.empty());
        ASSERT_FALSE(replay.scenes[0].empty());
        for (const CountingReplay::Frame& f : replay.scenes[0]) {
            const FrameObservation& o = f.observation;
            const double timed_at = 1000 + 200 * (o.inserts + o.removes + o.moves);
            EXPECT_NEAR(f.update_ns, timed_at, 0.1 * timed_at) << mode << " " << prices.to_json().dump();
        }
    }
}

TEST(TuneRecordsForAdvise, UpdatePricesRefuseWhatIsNotAPlainUpdateTerm) {
    const json good = {{"model", "m"}, {"terms", {{"c_change", 10.0}, {"c_frame", 100.0}}}};
    const UpdatePrices p = UpdatePrices::from_json(good, "t.json");
    FrameObservation o;
    o.moves = 3, o.inserts = 1;
    EXPECT_DOUBLE_EQ(p.per_frame_ns(o), 10.0 * 4 + 100.0);
    EXPECT_EQ(UpdatePrices::from_json(p.to_json(), "t.json").terms, p.terms);
    for (const json& bad :
         {json{{"terms", {{"C_RB", 1.0}}}}, json{{"terms", {{"c_change>L2", 1.0}}}},
          json{{"terms", {{"c_change", -1.0}}}}, json{{"terms", {{"c_change", "x"}}}}, json{{"model", "m"}}, json(3)}) {
        try {
            UpdatePrices::from_json(bad, "t.json: s");
            ADD_FAILURE() << bad.dump();
        } catch (const InputError& e) {
            EXPECT_EQ(std::string(e.what()).rfind("t.json: s.update_model", 0), 0u) << e.what();
        }
    }
}

/// Five configurations of one scene whose counters barely move (N_T about 10), timed at about
/// rays × (prep + t·10) with 5% noise: frames that hide the rays' work from a fit.
std::vector<FrameObservation> hidden_ray_work_frames(Random& rng, double t, double prep) {
    std::vector<FrameObservation> frames;
    for (int c = 0; c < 5; ++c)
        for (int f = 0; f < 4; ++f) {
            FrameObservation o;
            o.structure = "ug", o.scene = "u", o.category = "uniform";
            o.params = "{\"density\":" + std::to_string(c) + "}";
            o.config_group = c, o.rays = 200;
            o.n_t = 10 + c * (1 + 0.01 * rng.normal());
            o.raycast_ns = o.rays * (prep + t * 10) * (1 + 0.05 * rng.normal());
            frames.push_back(o);
        }
    return frames;
}

TEST(TuneCostModel, TheMachinesCalibrationKeepsRayWorkInAFewPointFit) {
    // Five configurations of one scene whose counters barely move, timed by a noisy machine that
    // hides the rays' work: the free fit prices it at 0 and leaves a start-up cost alone, which
    // ranks nothing; fitted again with the calibration's priors, C_T stays within 3x of its value.
    constexpr double kT = 4.0, kPrep = 30.0;
    Random rng(11);
    std::vector<FrameObservation> frames = hidden_ray_work_frames(rng, kT, kPrep);
    const std::optional<CostCoefficients> bare = fit_coefficients(frames);
    ASSERT_TRUE(bare.has_value());
    EXPECT_EQ((*bare)["C_T"], 0.0) << bare->to_json().dump();

    std::vector<CalibrationPoint> points;  // micro-scenes at C_T = 4, C_PREP = 30
    for (double n_t : {1.0, 20.0, 40.0, 60.0, 15.0, 120.0})
        points.push_back({"micro", 512, 0.0, n_t, (kT * n_t + kPrep) * (1 + 0.01 * rng.normal()), 0.1});
    ModelInputs priors;
    priors.calibrations.push_back(fit_calibration("ug", points));
    bool asked = false;
    const auto source = [&]() -> const ModelInputs& {
        asked = true;
        return priors;
    };
    const std::optional<CostCoefficients> pinned = fit_coefficients(frames, source);
    ASSERT_TRUE(pinned.has_value());
    EXPECT_GE((*pinned)["C_T"], kT / kPriorRange * 0.99) << pinned->to_json().dump();
    EXPECT_LE((*pinned)["C_T"], kT * kPriorRange * 1.01) << pinned->to_json().dump();
    EXPECT_NE(pinned->model.find("with the calibration's priors"), std::string::npos) << pinned->model;

    // Frames that do show the rays' work keep the free fit's balance: C_T = 20 where the
    // calibration says 4 (beyond its 3x range).
    for (FrameObservation& o : frames) o.raycast_ns = o.rays * (kPrep + 20 * o.n_t) * (1 + 0.01 * rng.normal());
    asked = false;
    const std::optional<CostCoefficients> free = fit_coefficients(frames, source);
    ASSERT_TRUE(free.has_value());
    EXPECT_NEAR((*free)["C_T"], 20, 2) << free->to_json().dump();
    EXPECT_EQ(free->model.find("priors"), std::string::npos) << free->model;
    EXPECT_FALSE(asked);  // the calibration is not even measured where the free fit prices the rays
}

TEST(TuneCostModel, AnUnpinnedCalibrationIsTheModelWhereNoFitPricesTheRays) {
    // The frames of the test above that hide the rays' work, and micro-scenes so noisy that no
    // coefficient is pinned: the priors bound nothing, so the bounded fit prices no ray work
    // either, and the model is the micro-scenes' own costs, named as such.
    constexpr double kT = 4.0, kPrep = 30.0;
    Random rng(11);
    std::vector<FrameObservation> frames = hidden_ray_work_frames(rng, kT, kPrep);
    std::vector<CalibrationPoint> points;  // three points, ±40%: every interval wider than ±50%
    for (auto [n_t, noise] : {std::pair{5.0, 1.4}, std::pair{40.0, 0.6}, std::pair{80.0, 1.3}})
        points.push_back({"micro", 512, 0.0, n_t, (kT * n_t + kPrep) * noise, 0.1});
    ModelInputs priors;
    priors.calibrations.push_back(fit_calibration("ug", points));
    const CalibratedTerm* t = priors.calibrations[0].term("C_T");
    ASSERT_NE(t, nullptr);
    ASSERT_FALSE(t->pinned) << t->why;
    ASSERT_GT(t->value, 0);
    const std::optional<CostCoefficients> alone =
        fit_coefficients(frames, [&]() -> const ModelInputs& { return priors; });
    ASSERT_TRUE(alone.has_value());
    EXPECT_DOUBLE_EQ((*alone)["C_T"], t->value) << alone->to_json().dump();
    EXPECT_NE(alone->model.find("calibration alone"), std::string::npos) << alone->model;
}

TEST(TuneCostModel, MachinePriorsCalibrateEveryBuildableStructure) {
    MachinePriors priors;
    for (const char* name : {"ug", "dbvh"}) {
        const ModelInputs& in = priors.of(name);
        ASSERT_EQ(in.calibrations.size(), 1u) << name;
        const StructureCalibration& c = in.calibrations[0];
        EXPECT_FALSE(c.points.empty()) << c.structure;
        const CalibratedTerm* t = c.term("C_T");
        ASSERT_NE(t, nullptr) << c.structure;
        // Fitted to timed micro-scenes, its size is the machine's; that there is one, finite and
        // not negative, is this test's (fit_calibration on made-up points: the tests above).
        EXPECT_TRUE(std::isfinite(t->value) && t->value >= 0) << c.structure << " " << t->value;
        EXPECT_EQ(&priors.of(name), &in);  // measured once, then kept
    }
}

/// Frames of one structure whose reported hits cost `c_hit` ns each beyond their box tests:
/// C = 0.8·N_RB + 5·N_T + 40 + c_hit·N_TP per ray, N_TP varying apart from N_RB across 16 configurations.
std::vector<FrameObservation> hit_priced_frames(double c_hit) {
    Random rng(21);
    std::vector<FrameObservation> frames;
    for (int c = 0; c < 16; ++c)
        for (int f = 0; f < 6; ++f) {
            FrameObservation o;
            o.structure = "bf", o.scene = "s" + std::to_string(c % 4), o.category = "uniform";
            o.params = "{\"c\":" + std::to_string(c) + "}";
            o.config_group = c, o.rays = 500;
            o.n_rb = 50 + 40 * (c % 4) + rng.uniform(0, 1);
            o.n_t = 10 + 7 * (c / 4) + rng.uniform(0, 1);
            o.n_tp = 1 + 3 * ((c * 7) % 5) + rng.uniform(0, 0.2);
            o.raycast_ns = o.rays * (0.8 * o.n_rb + 5 * o.n_t + 40 + c_hit * o.n_tp) * (1 + 0.005 * rng.normal());
            o.update_ns = 1000, o.memory_mb = 1;
            frames.push_back(o);
        }
    return frames;
}

TEST(TuneCostModel, AHitTermRoundTripsThroughATuningFileAndPricesHits) {
    // No kept form prices hits (docs/model.md, "Which forms are kept"): the free fit leaves C_HIT
    // at 0. A tuning that carries one (written by hand, or before the form was dropped) still
    // reaches the tuner.
    std::optional<CostCoefficients> fitted = fit_coefficients(hit_priced_frames(25.0));
    ASSERT_TRUE(fitted.has_value());
    EXPECT_EQ((*fitted)["C_HIT"], 0.0) << fitted->to_json().dump();
    (*fitted)["C_HIT"] = 25.0;

    // Written into a tuning file as run_tuning does and read back as advise does.
    const std::filesystem::path dir = test::temp_dir("tune", "hits");
    const std::string path = (dir / "tuning.json").string();
    {
        json tuning{
            {"categories",
             json::array({{{"category", "u"},
                           {"structures", json::array({{{"structure", "bf"}, {"cost_model", fitted->to_json()}}})}}})}};
        std::ofstream(path) << tuning.dump(2);
    }
    const json read = parse_json_document(read_text_file(path), path);
    const CostCoefficients back =
        CostCoefficients::from_json(read["categories"][0]["structures"][0]["cost_model"], path);
    EXPECT_EQ(back.to_json(), fitted->to_json());
    EXPECT_EQ(back["C_HIT"], (*fitted)["C_HIT"]);
    std::filesystem::remove_all(dir);

    // predict_cost prices the replay's hits with it: C_HIT·N_TP per frame more than without.
    // Made-up update times: the two replays' updates are then equal, and the difference is the hits' alone.
    const TuneCategory c{
        "u", {test::generated_spec("u", "uniform", 1500, 3, 200, {{"hits", 1}})}, test::counted_timing(1.0, 1.0, 1.0)};
    CostCoefficients without = back;
    without["C_HIT"] = 0;
    CostCoefficients priced = without;
    priced["C_HIT"] = 1e4;
    ReplayCounts counts;
    const double base = predict_cost(without, c, "ug", json::object(), 1, &counts);
    const double with_hits = predict_cost(priced, c, "ug", json::object(), 1);
    ASSERT_GT(counts.counters.n_tp, 0u);
    const double hits_ms_per_frame = 1e4 * double(counts.counters.n_tp) / 2 / 1e6;  // two measured frames
    EXPECT_NEAR(with_hits - base, hits_ms_per_frame, 1e-9 * hits_ms_per_frame);
}

TEST(TuneCostModel, TuningsWrittenBeforeTheHitTermReadWithoutIt) {
    // A cost_model as tunings wrote it before C_HIT (and before C_MP): absent reads as 0.
    const json older{{"model", "eq5.4"}, {"C_RB", 1.5}, {"C_T", 12.0}, {"C_PREP", 30.0},
                     {"C_MEM", 0.0},     {"C_RO", 0.0}, {"C_TH", 0.0}};
    const CostCoefficients c = CostCoefficients::from_json(older, "old.json");
    EXPECT_EQ(c["C_HIT"], 0.0);
    EXPECT_EQ(c["C_MP"], 0.0);
    EXPECT_EQ(c["C_T"], 12.0);
    FrameObservation f;
    f.n_rb = 2, f.n_t = 3, f.n_tp = 5;
    EXPECT_DOUBLE_EQ(c.per_ray(f), 1.5 * 2 + 12.0 * 3 + 30.0);
    // Present, it is read and priced like any term; not a number, it is refused with the file.
    json hits = older;
    hits["C_HIT"] = 4.0;
    EXPECT_DOUBLE_EQ(CostCoefficients::from_json(hits, "t.json").per_ray(f), 1.5 * 2 + 12.0 * 3 + 30.0 + 4.0 * 5);
    hits["C_HIT"] = "x";
    try {
        CostCoefficients::from_json(hits, "t.json");
        ADD_FAILURE() << "a non-numeric C_HIT was read";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("t.json: cost model coefficient C_HIT"), std::string::npos) << e.what();
    }
}

TEST(Tune, InterleavedMeasurementsGiveOneVerifiedCostPerConfiguration) {
    // The exhaustive checks' repetition-major measurement: one cost per configuration, in order,
    // verified on the first repetition when asked, each over every repetition's frames.
    const TuneCategory c{"u", {test::generated_spec("u", "uniform", 1500, 3, 100, {{"interleaved", 1}})}};
    const std::vector<json> params{find_structure("ug").complete({{"density", 1.0}}, "t"),
                                   find_structure("ug").complete({{"density", 8.0}}, "t"),
                                   find_structure("ug").complete({{"density", 1.0}, {"query", "candidates"}}, "t")};
    const std::vector<MeasuredCost> costs = measure_interleaved(c, "ug", params, 1, 2, true);
    ASSERT_EQ(costs.size(), 3u);
    for (const MeasuredCost& m : costs) {
        EXPECT_GT(m.ms, 0);
        EXPECT_TRUE(m.accuracy.verified);
        EXPECT_EQ(m.accuracy.mismatches, 0u);
    }
    EXPECT_TRUE(costs[0].accuracy.exact_level);
    EXPECT_FALSE(costs[2].accuracy.exact_level);  // the candidate level promises no upper side
    EXPECT_LT(costs[2].accuracy.precision, 1.0);  // and returns candidates the boxes rule out
    EXPECT_GT(costs[1].memory_bytes, 0);
}

}  // namespace
}  // namespace rcb

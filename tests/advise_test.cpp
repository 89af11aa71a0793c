// advise's choice of a tuned structure's parameters for a scene: the category's, or the category's
// cost model applied to the scene's own counters; its exhaustive check; and its bad inputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"
#include "tests/test_timing.h"
#include "tuner/advise.h"
#include "tuner/run_tuning.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const std::vector<double> kDensities{0.125, 0.25, 0.5, 1, 2, 4, 8, 16};

Recording uniform_scene(std::uint32_t objects, std::uint64_t seed) {
    SceneSettings s;
    s.generator = "uniform";
    s.objects = objects;
    s.seed = seed;
    s.frames = 3;
    s.rays.per_frame = 200;
    return generate_scene(s);
}

/// A tuning result as rcbench tune writes it, by hand: one category "c" whose UG was tuned to
/// `density` over kDensities, with the cost model `model` (none: null).
json tuning_with(double density, const json& model) {
    json ug = {{"structure", "ug"},
               {"best", {{"params", {{"density", density}}}}},
               {"space", json::array({{{"name", "density"}, {"levels", kDensities}}})}};
    if (!model.is_null()) ug["cost_model"] = model;
    return {{"name", "hand"},
            {"budget", 30},
            {"seed", 1},
            {"categories", json::array({{{"category", "c"}, {"structures", json::array({ug})}}})}};
}

json cost_model(double c_rb, double c_t) {
    return {{"model", "by hand"}, {"C_RB", c_rb}, {"C_T", c_t}, {"C_PREP", 0.0},
            {"C_MEM", 0.0},       {"C_RO", 0.0},  {"C_TH", 0.0}};
}

class AdviseFiles : public ::testing::Test {
protected:
    void SetUp() override { write_recording(uniform_scene(3000, 3), path("scene.rcbscene")); }
    std::string path(const std::string& name) const { return dir_.file(name); }
    std::string write_tuning(const std::string& name, const json& t) const {
        std::ofstream(path(name)) << t.dump(2);
        return path(name);
    }
    /// Advise on the scene with made-up times from its counters (C_RB 1, C_T 20, C_PREP 50 ns).
    /// These tests check choices among measured configurations and the model's ranking, whose
    /// predictions include the replays' update times: timed by the clock, such a choice flips on
    /// a loaded machine. PrintsTheScenesQueryKindsAndMotionAndWeighsByThem advises on the clock.
    AdviseOptions options(const std::string& tuning) const {
        AdviseOptions o;
        o.scene = path("scene.rcbscene");
        o.tuning = tuning;
        o.category = "c";
        o.repetitions = 1;
        o.warmup = 0;
        o.timing = test::counted_timing(1.0, 20.0, 50.0);
        return o;
    }
    static const ParameterChoice& ug_choice(const Advice& a) {
        for (const ParameterChoice& pc : a.parameters)
            if (pc.structure == "ug") return pc;
        throw std::logic_error("no ug choice");
    }
    test::TempDir dir_{"advise"};  // rcb_advise_<pid>_<test>, removed after the test
};

TEST_F(AdviseFiles, TheModelMethodFollowsTheCostOfAStepAgainstATest) {
    // UG's density is objects per cell. A cell step cheap against a box test: a fine grid (few
    // objects per cell, fewer tests per ray); an expensive one: a coarse grid (fewer cells walked).
    // Priced by the model alone (--verify-top 0), the advised density must rise with a step's price
    // against a test's, from the lowest level to the highest, whatever the category's tuned density
    // says. Per-ray terms of a microsecond and more drown the replay's timed update.
    AdviseOptions o = options("");
    o.verify_top = 0;
    double previous = 0;
    std::vector<double> chosen;
    for (double ratio : {1e-4, 1e-2, 1.0, 1e2, 1e4}) {  // C_T / C_RB
        o.tuning = write_tuning("t.json", tuning_with(1.0, cost_model(1e5 / std::sqrt(ratio), 1e5 * std::sqrt(ratio))));
        const Advice a = advise(o);
        const ParameterChoice& pc = ug_choice(a);
        ASSERT_EQ(pc.method, "model") << pc.why;
        EXPECT_EQ(pc.replays, kDensities.size());  // the space is within the budget: every level replayed
        const double d = pc.chosen_searched["density"].get<double>();
        EXPECT_GE(d, previous) << "C_T/C_RB " << ratio;
        previous = d;
        chosen.push_back(d);
        // The row advised for ug is the model's choice, predicted (the pure model times nothing).
        for (const AdviceRow& r : a.rows) {
            if (r.structure == "ug") {
                EXPECT_EQ(json::parse(r.params)["density"].get<double>(), d);
                EXPECT_TRUE(r.predicted);
            }
        }
    }
    EXPECT_EQ(chosen.front(), kDensities.front());
    EXPECT_EQ(chosen.back(), kDensities.back());
}

TEST_F(AdviseFiles, MeasuresTheModelsBestBesideTheCategorysAndKeepsTheFastest) {
    AdviseOptions o = options(write_tuning("t.json", tuning_with(0.125, cost_model(2.0, 20.0))));
    o.verify_top = 2;
    o.refine = 0;
    const Advice a = advise(o);
    const ParameterChoice& pc = ug_choice(a);
    ASSERT_EQ(pc.method, "model");
    EXPECT_NE(pc.why.find("cost model"), std::string::npos) << pc.why;
    std::size_t measured = 0;
    bool category_measured = false;
    double fastest = INFINITY;
    for (const ModelCandidate& c : pc.candidates) {
        EXPECT_TRUE(c.predicted_ms.has_value());  // every level was replayed
        if (!c.measured) continue;
        ++measured;
        category_measured |= c.is_category;
        fastest = std::min(fastest, c.measured->ms);
    }
    EXPECT_EQ(measured, 3u);  // the model's two best and the category's finest grid
    EXPECT_TRUE(category_measured);
    ASSERT_TRUE(pc.candidates.front().measured.has_value());
    EXPECT_EQ(pc.candidates.front().measured->ms, fastest);  // the fastest measured is advised
    EXPECT_EQ(pc.chosen_searched, pc.candidates.front().searched);
    EXPECT_NE(pc.summary.find("fastest measured"), std::string::npos) << pc.summary;
}

TEST_F(AdviseFiles, AMeasuredDescentCorrectsAModelThatMisranks) {
    // A model that prices a box test a million times a cell step ranks the finest grid (1/8 of an
    // object per cell) first; where a step costs 20 box tests (the fixture's times), on 3000
    // uniform boxes a coarser grid is faster, and the descent from the verified best walks up the
    // densities, one level at a time, within its measurements.
    AdviseOptions o = options(write_tuning("t.json", tuning_with(0.125, cost_model(1e4, 0.01))));
    o.verify_top = 1;
    o.refine = 4;
    const Advice a = advise(o);
    const ParameterChoice& pc = ug_choice(a);
    ASSERT_EQ(pc.method, "model");
    EXPECT_GE(pc.refined, 1u);
    EXPECT_LE(pc.refined, 4u);
    std::vector<double> measured;
    for (const ModelCandidate& c : pc.candidates)
        if (c.measured) measured.push_back(c.searched["density"].get<double>());
    EXPECT_EQ(measured.size(), 1 + pc.refined);  // the verified best (the category's) and the descent
    std::sort(measured.begin(), measured.end());
    EXPECT_EQ(std::adjacent_find(measured.begin(), measured.end()), measured.end());  // none twice
    EXPECT_GT(pc.chosen_searched["density"].get<double>(), 0.125) << pc.summary;
    EXPECT_NE(pc.summary.find("by the measured descent"), std::string::npos) << pc.summary;

    o.refine = 0;  // the model's best and the category's, nothing more
    EXPECT_EQ(ug_choice(advise(o)).refined, 0u);
}

TEST_F(AdviseFiles, WithoutACostModelAutoKeepsTheCategorysParametersAndSaysWhy) {
    const std::string t = write_tuning("t.json", tuning_with(2.0, nullptr));
    const Advice a = advise(options(t));
    const ParameterChoice& pc = ug_choice(a);
    EXPECT_EQ(pc.method, "category");
    EXPECT_NE(pc.why.find("no cost model"), std::string::npos) << pc.why;
    EXPECT_EQ(pc.chosen_searched["density"].get<double>(), 2.0);
    // --method category keeps them even where a model exists.
    AdviseOptions o = options(write_tuning("m.json", tuning_with(2.0, cost_model(1.0, 10.0))));
    o.method = "category";
    EXPECT_EQ(ug_choice(advise(o)).method, "category");
    // --method model insists on one.
    o = options(t);
    o.method = "model";
    EXPECT_THROW(advise(o), InputError);
}

TEST_F(AdviseFiles, AParameterRecordedOnlyAwayFromItsDefaultStillStartsTheSearch) {
    // A tuning that searched the query level records a best at the default level (boxes) without
    // it; the category's point in the space must still be the boxes level, not the middle one.
    json t = tuning_with(1.0, cost_model(2.0, 20.0));
    t["categories"][0]["structures"][0]["space"].push_back(
        {{"name", "query"}, {"levels", json::array({"candidates", "boxes", "shapes"})}});
    AdviseOptions o = options(write_tuning("t.json", t));
    o.verify_top = 1;
    const Advice a = advise(o);
    const ParameterChoice& pc = ug_choice(a);
    EXPECT_EQ(pc.category_searched["query"], "boxes");
    EXPECT_EQ(pc.category_searched["density"].get<double>(), 1.0);
    bool category_measured = false;
    for (const ModelCandidate& c : pc.candidates) category_measured |= c.is_category && c.measured.has_value();
    EXPECT_TRUE(category_measured);
}

TEST_F(AdviseFiles, TheExhaustiveCheckMeasuresTheWholeSpaceOnTheScene) {
    AdviseOptions o = options(write_tuning("t.json", tuning_with(4.0, cost_model(2.0, 20.0))));
    o.exhaustive = true;
    const Advice a = advise(o);
    ASSERT_EQ(a.exhaustive.size(), 1u);
    const ExhaustiveAdvice& e = a.exhaustive[0];
    EXPECT_EQ(e.structure, "ug");
    EXPECT_EQ(e.configurations, kDensities.size());
    EXPECT_GT(e.best_ms, 0);
    EXPECT_GE(e.advised_gap(), 0.0);  // the scene's best is the least of the same measurements
    EXPECT_GE(e.category_gap(), 0.0);
    EXPECT_EQ(e.category_searched["density"].get<double>(), 4.0);
    EXPECT_EQ(e.advised_searched, ug_choice(a).chosen_searched);
    // The JSON form carries the same figures.
    const json j = advice_json(a, o);
    EXPECT_EQ(j["parameters"][0]["method"], "model");
    EXPECT_DOUBLE_EQ(j["exhaustive"][0]["advised_gap"].get<double>(), e.advised_gap());
    EXPECT_EQ(j["rows"].size(), a.rows.size());
}

TEST_F(AdviseFiles, TheBudgetCountsExactlyWhatWasTimedAndReplayed) {
    // The tuner's measuring path tallies every simulation it runs (timed, or an untimed counting
    // replay); advise's reported budget must account for each of them, per tuned structure, with
    // every untuned structure's row measured once at its defaults beside it.
    for (const char* method : {"model", "category"}) {
        AdviseOptions o = options(write_tuning("t.json", tuning_with(0.125, cost_model(2.0, 20.0))));
        o.method = method;
        o.repetitions = 2;
        o.refine = 2;
        const SimulationTally before = simulation_tally();
        const Advice a = advise(o);
        const SimulationTally after = simulation_tally();
        const ParameterChoice& pc = ug_choice(a);
        const AdviseBudget& b = pc.budget;
        const std::size_t untuned = a.rows.size() - 1;  // exact accuracy: one row per structure
        EXPECT_EQ(after.timed - before.timed, b.timed_measurements + untuned * o.repetitions) << method;
        EXPECT_EQ(after.counting - before.counting, b.replays) << method;
        EXPECT_EQ(b.timed_measurements, b.timed * o.repetitions) << method;  // no configuration timed twice
        EXPECT_EQ(b.space, kDensities.size());
        if (std::string(method) == "model") {
            std::size_t measured = 0;
            for (const ModelCandidate& c : pc.candidates) measured += c.measured.has_value();
            EXPECT_EQ(b.timed, measured);             // the advised row reuses its candidate's measurement
            EXPECT_GE(b.timed, 2u);                   // the model's best and the category's at least
            EXPECT_EQ(b.replays, kDensities.size());  // the space within the budget: each level once
        } else {
            EXPECT_EQ(b.timed, 1u);  // the category's parameters, measured for their row
            EXPECT_EQ(b.replays, 0u);
        }
        // A tuning without update prices: every replay timed the scene's update, and says so.
        EXPECT_EQ(b.replays_update_timed, b.replays) << method;
        EXPECT_EQ(after.counting_update_timed - before.counting_update_timed, b.replays) << method;
        const json j = advice_json(a, o)["parameters"][0]["budget"];
        EXPECT_EQ(j, (json{{"timed", b.timed},
                           {"timed_measurements", b.timed_measurements},
                           {"replays", b.replays},
                           {"replays_update_timed", b.replays_update_timed},
                           {"space", b.space}}));
    }
}

TEST_F(AdviseFiles, ExhaustiveReportsThePureModelAndBaselinesOfTheSameBudget) {
    // A step priced far above a box test: the model alone ranks the coarsest grid first, whatever
    // the replay's timed update adds, so two runs replay to the same prediction.
    AdviseOptions o = options(write_tuning("t.json", tuning_with(2.0, cost_model(1e3, 1e7))));
    o.exhaustive = true;
    o.seed = 5;
    const Advice full = advise(o);
    const ParameterChoice& pc = ug_choice(full);
    ASSERT_TRUE(pc.predicted_best.has_value());
    ASSERT_EQ(full.exhaustive.size(), 1u);
    const ExhaustiveAdvice& e = full.exhaustive[0];
    EXPECT_EQ(e.budget, pc.budget);
    std::vector<std::string> names;
    for (const MethodOutcome& m : e.methods) names.push_back(m.method);
    ASSERT_EQ(names, (std::vector<std::string>{"advise", "advise-table", "model", "category", "random", "descent"}));
    EXPECT_EQ(e.methods[0].searched, pc.chosen_searched);
    EXPECT_DOUBLE_EQ(e.methods[0].regret, e.advised_gap());
    // advise's steps on the first table: the predicted best and the category's at least, at most the space.
    EXPECT_GE(e.methods[1].timed, 2u);
    EXPECT_LE(e.methods[1].timed, kDensities.size());
    EXPECT_EQ(e.methods[2].searched, *pc.predicted_best);
    EXPECT_DOUBLE_EQ(e.methods[3].regret, e.category_gap());
    // The same budget: advise's timed configurations and replays (random times one configuration
    // per structure in effect among those it replayed).
    EXPECT_LE(e.methods[4].timed, pc.budget.timed);
    EXPECT_GT(e.methods[4].timed, 0u);
    EXPECT_EQ(e.methods[4].replays, std::min(pc.budget.replays, kDensities.size()));
    EXPECT_LE(e.methods[5].timed, pc.budget.timed);
    EXPECT_GT(e.methods[5].timed, 0u);
    EXPECT_LE(e.methods[5].replays, pc.budget.replays);
    EXPECT_EQ(e.methods[0].replays, pc.budget.replays);
    EXPECT_EQ(e.methods[2].timed, 0u);  // the pure model
    EXPECT_EQ(e.methods[2].replays, pc.budget.replays);
    // Made-up times repeat exactly, so the re-measurement equals the table: none beats its best.
    EXPECT_DOUBLE_EQ(e.best_ms, e.best_table_ms);
    for (const MethodOutcome& m : e.methods) EXPECT_GE(m.regret, 0.0) << m.method;
    const json j = advice_json(full, o);
    EXPECT_EQ(j["baseline_seed"], 5);
    EXPECT_EQ(j["exhaustive"][0]["methods"].size(), 6u);
    EXPECT_EQ(j["exhaustive"][0]["methods"][2]["params"], *pc.predicted_best);

    // --verify-top 0 --refine 0 advises the pure-model choice.
    o.exhaustive = false;
    o.verify_top = 0;
    o.refine = 0;
    const Advice pure_advice = advise(o);
    const ParameterChoice& pure = ug_choice(pure_advice);
    EXPECT_EQ(pure.chosen_searched, *pc.predicted_best);
    EXPECT_EQ(pure.chosen_searched, *pure.predicted_best);
    EXPECT_EQ(pure.budget.timed, 0u);  // the pure model: its row is the prediction
}

TEST_F(AdviseFiles, ReplaysSetHowMuchOfTheSpaceThePureModelRanks) {
    // The tuning's search budget (4) replays part of the 8-level space; --replays 8 ranks all of
    // it, and --replays 2 stays below the tuning's budget. The pure model times none of them.
    json t = tuning_with(1.0, cost_model(2.0, 20.0));
    t["budget"] = 4;
    AdviseOptions o = options(write_tuning("t.json", t));
    o.method = "model";
    o.verify_top = 0;
    o.refine = 0;
    const Advice by_tuning = advise(o);
    EXPECT_LE(ug_choice(by_tuning).budget.replays, 4u);
    EXPECT_NE(ug_choice(by_tuning).ranking->search.algorithm, "enumeration");
    o.replays = kDensities.size();
    const Advice whole = advise(o);
    EXPECT_EQ(ug_choice(whole).budget.replays, kDensities.size());
    EXPECT_EQ(ug_choice(whole).ranking->search.algorithm, "enumeration");
    EXPECT_EQ(ug_choice(whole).budget.timed, 0u);
    o.replays = 2;
    EXPECT_LE(ug_choice(advise(o)).budget.replays, 2u);
}

TEST_F(AdviseFiles, ThePureModelTimesNothingOnTheScene) {
    // --verify-top 0 with a tuning that holds the update's prices: the replays predict the update,
    // no candidate and no row is measured, so the simulator times no build, update or ray batch.
    json t = tuning_with(1.0, cost_model(2.0, 20.0));
    t["categories"][0]["structures"][0]["update_model"] = {
        {"model", "by hand"}, {"terms", {{"c_change", 100.0}, {"c_object", 5.0}, {"c_frame", 1000.0}}}};
    AdviseOptions o = options(write_tuning("t.json", t));
    o.method = "model";
    o.verify_top = 0;
    const std::uint64_t phases = timed_phases();
    const SimulationTally before = simulation_tally();
    const Advice a = advise(o);
    const SimulationTally after = simulation_tally();
    EXPECT_EQ(timed_phases(), phases);  // nothing timed on the scene, the update included
    EXPECT_EQ(after.timed, before.timed);
    EXPECT_EQ(after.counting_update_timed, before.counting_update_timed);
    const ParameterChoice& pc = ug_choice(a);
    EXPECT_EQ(pc.budget.timed, 0u);
    EXPECT_EQ(pc.budget.timed_measurements, 0u);
    EXPECT_EQ(pc.budget.replays_update_timed, 0u);
    EXPECT_EQ(after.counting - before.counting, pc.budget.replays);
    EXPECT_NE(pc.summary.find("nothing timed"), std::string::npos) << pc.summary;
    // The advised row is the prediction; every other structure, without a model, is unpriced and
    // never recommended.
    ASSERT_TRUE(a.recommended.has_value());
    EXPECT_EQ(a.rows[*a.recommended].structure, "ug");
    for (const AdviceRow& r : a.rows) {
        EXPECT_EQ(r.predicted, r.structure == "ug") << r.structure;
        EXPECT_EQ(r.priced(), r.structure == "ug") << r.structure;
    }
    const json j = advice_json(a, o);
    EXPECT_EQ(j["parameters"][0]["budget"]["timed"], 0);
    // An inexact --accuracy needs verifying, which the pure model cannot do.
    o.accuracy = parse_accuracy("recall>=0.9");
    EXPECT_THROW(advise(o), InputError);
}

TEST(AdviseCounts, ConfigurationsThatAreOneStructureInEffectCountAlike) {
    // A hash grid of depth 0 never splits a cell: its capacity and subdivision change nothing.
    const TuneCategory c{"u", {test::generated_spec("u", "uniform", 2000, 2, 100, {{"advise-counts", 1}})}};
    const CostCoefficients model = CostCoefficients::from_json(cost_model(1.0, 10.0), "test");
    auto counts = [&](const json& p) {
        ReplayCounts r;
        predict_cost(model, c, "hg", p, 0, &r);
        return r;
    };
    const ReplayCounts flat8 = counts({{"amp", 1.0}, {"max_depth", 0}, {"max_capacity", 8}, {"subdivision", 2}});
    const ReplayCounts flat32 = counts({{"amp", 1.0}, {"max_depth", 0}, {"max_capacity", 32}, {"subdivision", 3}});
    EXPECT_EQ(flat8, flat32);
    EXPECT_GT(flat8.counters.n_t, 0u);
    EXPECT_NE(flat8, counts({{"amp", 0.25}, {"max_depth", 0}, {"max_capacity", 8}, {"subdivision", 2}}));
}

TEST(AdviseCostModel, RoundTripsAndRefusesNonFiniteCoefficients) {
    const CostCoefficients c = CostCoefficients::from_json(cost_model(1.5, 12.0), "t.json");
    EXPECT_EQ(c["C_RB"], 1.5);
    EXPECT_EQ(c["C_T"], 12.0);
    EXPECT_EQ(CostCoefficients::from_json(c.to_json(), "again").to_json(), c.to_json());
    json bad = cost_model(1.5, 12.0);
    bad["C_T"] = "x";
    EXPECT_THROW(CostCoefficients::from_json(bad, "t.json"), InputError);
    bad.erase("C_T");
    EXPECT_THROW(CostCoefficients::from_json(bad, "t.json"), InputError);
    // C_MP (coherence) is optional: a tuning written before it prices no unpredicted step.
    json older = cost_model(1.5, 12.0);
    older.erase("C_MP");
    EXPECT_EQ(CostCoefficients::from_json(older, "old.json")["C_MP"], 0.0);
    json coherent = cost_model(1.5, 12.0);
    coherent["C_MP"] = 9.0;
    EXPECT_EQ(CostCoefficients::from_json(coherent, "t.json")["C_MP"], 9.0);
    coherent["C_MP"] = "fast";
    EXPECT_THROW(CostCoefficients::from_json(coherent, "t.json"), InputError);
}

TEST_F(AdviseFiles, BadOptionsAndTuningsAreOneLineErrors) {
    const std::string bin = RCBENCH_BINARY, scene = path("scene.rcbscene");
    auto expect_bad = [](const ::test::Outcome& r, const std::string& needle) {
        EXPECT_EQ(r.code, 2) << r.err;
        EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    };
    const std::string none = write_tuning("none.json", tuning_with(2.0, nullptr));
    expect_bad(::test::run_shell(bin + " advise " + scene + " --method bogus"), "--method");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --verify-top 17"), "--verify-top");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --verify-top -1"), "--verify-top");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --verify-top x"), "--verify-top");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --replays 0"), "--replays");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --exhaustive"), "--exhaustive needs --tuning");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --tuning " + none + " --category c --method model"),
               "none.json");
    json t = tuning_with(2.0, cost_model(1.0, 10.0));
    t["categories"][0]["structures"][0]["cost_model"]["C_RB"] = "fast";
    expect_bad(
        ::test::run_shell(bin + " advise " + scene + " --tuning " + write_tuning("nan.json", t) + " --category c"),
        "C_RB");
    t = tuning_with(2.0, cost_model(1.0, 10.0));
    t["categories"][0]["structures"][0]["space"][0]["levels"] = json::array({1, -3});
    expect_bad(
        ::test::run_shell(bin + " advise " + scene + " --tuning " + write_tuning("lv.json", t) + " --category c"),
        "lv.json");
    t = tuning_with(2.0, cost_model(1.0, 10.0));
    t["categories"][0]["structures"][0].erase("space");
    expect_bad(::test::run_shell(bin + " advise " + scene + " --tuning " + write_tuning("old.json", t) +
                                 " --category c --exhaustive"),
               "records no search space");
}

TEST_F(AdviseFiles, PrintsTheScenesQueryKindsAndMotionAndWeighsByThem) {
    // A scene of game queries whose 5% of objects change per frame: advise reports those, not the
    // thesis' 1% and all-hits rays, and its per-frame costs are that scene's update plus ray cast.
    SceneSettings s;
    s.generator = "uniform";
    s.objects = 2000;
    s.frames = 3;
    s.dynamics.change_fraction = 0.05;
    s.dynamics.insert_share = s.dynamics.remove_share = 0;
    s.rays.per_frame = 100;
    s.rays = with_query_preset(s.rays, "game");
    write_recording(generate_scene(s), path("game.rcbscene"));
    AdviseOptions o;
    o.scene = path("game.rcbscene");
    o.repetitions = 1;
    o.warmup = 0;
    const Advice a = advise(o);
    EXPECT_DOUBLE_EQ(a.workload.kind_share(QueryKind::closest), 0.5);
    EXPECT_DOUBLE_EQ(a.workload.kind_share(QueryKind::any), 0.3);
    EXPECT_DOUBLE_EQ(a.workload.kind_share(QueryKind::all), 0.2);
    EXPECT_NEAR(a.workload.changed_p50, 0.05, 1e-3);
    EXPECT_DOUBLE_EQ(a.workload.changes_per_frame, 100.0);
    EXPECT_GT(a.workload.move_median, 0.0);
    EXPECT_NE(a.workload_text.find("100 rays (closest 50.0%, any 30.0%, all 20.0%)"), std::string::npos)
        << a.workload_text;
    EXPECT_NE(a.workload_text.find("p50 5.0%"), std::string::npos) << a.workload_text;
    const json j = advice_json(a, o);
    EXPECT_EQ(j["workload"]["query_kinds"], json({{"all", 60}, {"closest", 150}, {"any", 90}}));
    EXPECT_NEAR(j["workload"]["motion"]["changed_share"]["p90"].get<double>(), 0.05, 1e-3);
    EXPECT_EQ(j["workload"]["summary"], a.workload_text);
    // A boxes CSV has no motion or rays of its own: the summary says which it was given.
    EXPECT_NE(workload_summary(a.workload, true).find("10 frames of 1% dynamics and 1000 centre rays"),
              std::string::npos);
}

}  // namespace
}  // namespace rcb

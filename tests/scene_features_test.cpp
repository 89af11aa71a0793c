// Scene features, categories derived from them, and advice that picks a category from a scene.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "analysis/scene_categories.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tuner/advise.h"
#include "tuner/run_tuning.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

Recording scene(const std::string& generator, std::uint32_t objects, std::uint64_t seed) {
    SceneSettings s;
    s.generator = generator;
    s.objects = objects;
    s.seed = seed;
    s.frames = 3;
    s.rays.per_frame = 200;
    return generate_scene(s);
}

std::size_t feature(std::string_view name) {
    for (std::size_t i = 0; i < kSceneFeatureCount; ++i)
        if (scene_feature_names()[i] == name) return i;
    ADD_FAILURE() << name;
    return 0;
}

class SceneCategoryFiles : public ::testing::Test {
protected:
    std::string path(const std::string& name) const { return dir_.file(name); }
    test::TempDir dir_{"features"};  // rcb_features_<pid>_<test>, removed after the test
};

TEST(SceneFeatures, AreDeterministicForASeed) {
    const std::string a = compute_scene_features(scene("irregular", 3000, 5)).to_json().dump();
    const std::string b = compute_scene_features(scene("irregular", 3000, 5)).to_json().dump();
    const std::string c = compute_scene_features(scene("irregular", 3000, 6)).to_json().dump();
    EXPECT_EQ(a, b);
    EXPECT_NE(a, c);  // another seed is another scene
    const SceneFeatures f = SceneFeatures::from_json(nlohmann::json::parse(a), "a");
    EXPECT_EQ(f.to_json().dump(), a);  // round trip, bit for bit
}

TEST(SceneFeatures, TellUniformFromIrregularScenes) {
    const SceneFeatures u = compute_scene_features(scene("uniform", 3000, 1));
    const SceneFeatures i = compute_scene_features(scene("irregular", 3000, 1));
    EXPECT_DOUBLE_EQ(u.values[feature("log10_objects")], std::log10(3000.0));
    EXPECT_LT(u.values[feature("size_spread")], i.values[feature("size_spread")]);  // one size vs many (§6.1)
    EXPECT_GT(u.values[feature("occupancy")], i.values[feature("occupancy")]);      // spread out vs clustered
    EXPECT_LT(u.values[feature("log10_count_cv")], i.values[feature("log10_count_cv")]);
    EXPECT_GT(u.values[feature("occupancy")], 0.9);  // the uniform generator puts one object per cell
    EXPECT_LT(i.values[feature("occupancy")], 0.5);
    for (double v : u.values) EXPECT_TRUE(std::isfinite(v));
    EXPECT_GT(u.values[feature("log10_hits_per_ray")], 0);
    EXPECT_GT(u.values[feature("log10_cells_per_ray")], 0);
    EXPECT_NEAR(u.values[feature("change_rate")], 0.01, 0.002);  // the default 1% per frame
}

TEST(SceneFeatures, AnEmptySceneHasFiniteFeatures) {
    const SceneFeatures f = compute_scene_features(Recording{});
    for (double v : f.values) EXPECT_TRUE(std::isfinite(v));
}

TEST(SceneFeatures, MalformedStoredFeaturesAreInputErrors) {
    nlohmann::json j = compute_scene_features(scene("uniform", 200, 1)).to_json();
    j.erase("occupancy");
    EXPECT_THROW(SceneFeatures::from_json(j, "x"), InputError);
}

TEST(DerivedCategories, SeparateTwoGroupsOfGeneratedScenes) {
    std::vector<SceneFeatures> f;
    std::vector<std::string> fixed;
    for (std::uint64_t seed : {1, 2, 3}) f.push_back(compute_scene_features(scene("uniform", 1500, seed)));
    for (std::uint64_t seed : {1, 2, 3}) f.push_back(compute_scene_features(scene("irregular", 4000, seed)));
    for (int i = 0; i < 6; ++i) fixed.push_back(i < 3 ? "uniform" : "irregular");
    const SceneClustering c = cluster_scenes(f, fixed, 1);
    ASSERT_EQ(c.categories.size(), 2u) << c.rule;
    EXPECT_EQ(c.categories[0].members, (std::vector<std::size_t>{0, 1, 2}));
    EXPECT_EQ(c.categories[1].members, (std::vector<std::size_t>{3, 4, 5}));
    EXPECT_EQ(c.categories[0].nearest_fixed, "uniform");
    EXPECT_EQ(c.categories[0].name.rfind("uniform-", 0), 0u) << c.categories[0].name;
    EXPECT_EQ(c.categories[1].name.rfind("irregular-", 0), 0u) << c.categories[1].name;
    EXPECT_GT(c.silhouette, 0.25);
    EXPECT_EQ(cluster_scenes(f, fixed, 1).to_json().dump(), c.to_json().dump());  // deterministic for a seed
    // Round trip through the tuning file's block, and matching of unseen scenes.
    const SceneClustering back = SceneClustering::from_json(c.to_json(), "t.json");
    EXPECT_EQ(nearest_category(back, compute_scene_features(scene("uniform", 1500, 9))).category, 0u);
    EXPECT_EQ(nearest_category(back, compute_scene_features(scene("irregular", 4000, 9))).category, 1u);
}

TEST(DerivedCategories, OneCategoryWhenTheScenesDoNotDiffer) {
    std::vector<SceneFeatures> f;
    for (std::uint64_t seed : {1, 2, 3, 4}) f.push_back(compute_scene_features(scene("uniform", 1500, seed)));
    // Seeds of one generator differ only by noise; the scaling magnifies it, so a structureless
    // group must not be split: every scene here has the same generator and size.
    const SceneClustering c = cluster_scenes(f, {}, 1);
    ASSERT_EQ(c.categories.size(), 1u) << c.rule;
    EXPECT_EQ(c.categories[0].members.size(), 4u);
    EXPECT_EQ(c.categories[0].name, "scenes");  // no fixed category given, nothing sets it apart
    EXPECT_EQ(cluster_scenes({f[0]}, {}, 1).categories.size(), 1u);
    EXPECT_THROW(cluster_scenes({}, {}, 1), InputError);
}

TEST_F(SceneCategoryFiles, AdviseWithoutACategoryPicksTheCategoryOfTheScenesItResembles) {
    TuneSpec spec = parse_tune_spec(
        R"({"name": "two", "structures": ["ug"], "mode": "measured", "budget": 2, "frames": 2,
            "rays_per_frame": 100, "repetitions": 1, "warmup_frames": 0,
            "space": {"ug": {"density": [1, 4]}},
            "categories": [{"name": "given", "scenes": [
                {"generator": "uniform", "objects": 1500, "seed": 1}, {"generator": "uniform", "objects": 1500, "seed": 2},
                {"generator": "uniform", "objects": 1500, "seed": 3}, {"generator": "irregular", "objects": 4000, "seed": 1},
                {"generator": "irregular", "objects": 4000, "seed": 2}, {"generator": "irregular", "objects": 4000, "seed": 3}]}]})",
        "two.json", dir_.path().string());
    TuneOptions o;
    o.file = path("two.json");
    o.db = path("r.db");
    o.out_dir = dir_.path().string();
    o.derive_categories = true;
    const TuneOutcome out = run_tuning(spec, o);
    ASSERT_EQ(out.categories.size(), 2u) << out.scene_categories.rule;
    const std::string uniform = out.categories[0].category, irregular = out.categories[1].category;
    EXPECT_EQ(uniform.rfind("uniform-", 0), 0u) << uniform;
    EXPECT_EQ(irregular.rfind("irregular-", 0), 0u) << irregular;

    write_recording(scene("uniform", 1500, 17), path("unseen-uniform.rcbscene"));
    write_recording(scene("irregular", 4000, 17), path("unseen-irregular.rcbscene"));
    AdviseOptions a;
    a.scene = path("unseen-uniform.rcbscene");
    a.tuning = out.json_path;
    a.repetitions = 1;
    a.warmup = 0;
    const Advice advice = advise(a);
    ASSERT_TRUE(advice.chosen.has_value());
    EXPECT_EQ(advice.chosen->category, uniform);
    EXPECT_NE(advice.chosen->explanation.find(uniform), std::string::npos) << advice.chosen->explanation;
    bool tuned_ug = false;
    for (const AdviceRow& r : advice.rows) tuned_ug |= r.structure == "ug" && r.tuned;
    EXPECT_TRUE(tuned_ug);  // the chosen category's parameters were used
    // ... and the advice says how it chose them, from the category it matched.
    ASSERT_EQ(advice.parameters.size(), 1u);
    EXPECT_EQ(advice.parameters[0].structure, "ug");
    EXPECT_FALSE(advice.parameters[0].why.empty());
    EXPECT_NE(advice.parameters[0].summary.find(uniform), std::string::npos) << advice.parameters[0].summary;

    const nlohmann::json t = nlohmann::json::parse(std::ifstream(out.json_path));
    EXPECT_EQ(choose_category(out.json_path, t, read_recording(path("unseen-irregular.rcbscene"))).category, irregular);
    // --category still decides when given.
    a.category = irregular;
    EXPECT_FALSE(advise(a).chosen.has_value());
}

TEST_F(SceneCategoryFiles, RunsStoreFeaturesAndDeriveCategoriesOrSayWhyNot) {
    const std::string bin = RCBENCH_BINARY, db = path("r.db"), exp = path("e.json");
    std::ofstream(exp) << R"({"name": "feat", "frames": 2, "rays_per_frame": 50, "repetitions": 1, "seeds": [1],
        "scenes": [{"generator": "uniform", "objects": 800}, {"generator": "uniform", "objects": 900},
                   {"generator": "irregular", "objects": 3000}, {"generator": "irregular", "objects": 3500}],
        "structures": [{"name": "bf"}]})";
    const ::test::Outcome run = ::test::run_shell(bin + " run " + exp + " --db " + db);
    ASSERT_EQ(run.code, 0) << run.err;
    {
        auto d = open_read_only(db);
        Statement s = d->prepare("SELECT count(DISTINCT scene_id), count(*) FROM scene_feature");
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 4);
        EXPECT_EQ(s.int64(1), 4 * std::int64_t(kSceneFeatureCount));
    }
    // merge copies the scenes' features with the scenes.
    const ::test::Outcome merged = ::test::run_shell(bin + " merge " + path("m.db") + " " + db);
    ASSERT_EQ(merged.code, 0) << merged.err;
    {
        auto d = open_read_only(path("m.db"));
        Statement s = d->prepare("SELECT count(*) FROM scene_feature");
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 4 * std::int64_t(kSceneFeatureCount));
    }
    const ::test::Outcome cats = ::test::run_shell(bin + " categories " + db);
    ASSERT_EQ(cats.code, 0) << cats.err;
    EXPECT_NE(cats.out.find("2 categories"), std::string::npos) << cats.out;
    {
        auto d = open_read_only(db);
        Statement s = d->prepare("SELECT count(*), count(DISTINCT category) FROM derived_category_scene");
        ASSERT_TRUE(s.step());
        EXPECT_EQ(s.int64(0), 4);
        EXPECT_EQ(s.int64(1), 2);
    }
    // A database whose scenes have no features (an older rcbench stored them): one line, exit 2.
    {
        ResultStore store(db);
        store.db().exec("DELETE FROM scene_feature");
    }
    const ::test::Outcome old = ::test::run_shell(bin + " categories " + db);
    EXPECT_EQ(old.code, 2) << old.err;
    EXPECT_NE(old.err.find("has no stored features"), std::string::npos) << old.err;
    EXPECT_EQ(std::count(old.err.begin(), old.err.end(), '\n'), 1) << old.err;
    // A new run of the same scenes stores their features again.
    ASSERT_EQ(::test::run_shell(bin + " run " + exp + " --db " + db + " --new-run").code, 0);
    const ::test::Outcome again = ::test::run_shell(bin + " categories " + db);
    EXPECT_EQ(again.code, 0) << again.err;
}

TEST_F(SceneCategoryFiles, BadInputsToFeaturesAndAdviceAreOneLineErrors) {
    const std::string bin = RCBENCH_BINARY;
    auto expect_bad = [](const ::test::Outcome& r, const std::string& needle) {
        EXPECT_EQ(r.code, 2) << r.err;
        EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    };
    expect_bad(::test::run_shell(bin + " scene features " + path("missing.rcbscene")), "missing.rcbscene");
    write_recording(scene("uniform", 300, 1), path("s.rcbscene"));
    const ::test::Outcome f = ::test::run_shell(bin + " scene features --json " + path("s.rcbscene"));
    ASSERT_EQ(f.code, 0) << f.err;
    EXPECT_EQ(nlohmann::json::parse(f.out).size(), kSceneFeatureCount);
    // A tuning result without scene categories (an older rcbench wrote it) and no --category.
    std::ofstream(path("old.json")) << R"({"name": "old", "categories": [{"category": "c", "structures": []}]})";
    expect_bad(::test::run_shell(bin + " advise " + path("s.rcbscene") + " --tuning " + path("old.json")),
               "no scene categories");
    expect_bad(::test::run_shell(bin + " advise " + path("missing.rcbscene") + " --tuning " + path("old.json")),
               "missing.rcbscene");
    expect_bad(::test::run_shell(bin + " categories " + path("missing.db")), "missing.db");
}

}  // namespace
}  // namespace rcb

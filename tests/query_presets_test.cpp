// Game query presets (generators.h, query_preset_mix): each ray carries its mode's kind, the rays
// start outside their agent, the same seed gives the same bytes, scenes without a preset keep their
// bytes, the preset is recorded in the meta and shown by scene info; experiment entries take presets,
// physics generators and a time step, and refuse what does not apply, naming the JSON path.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/generate/physics.h"
#include "core/scene/recording_io.h"
#include "core/scene/workload.h"
#include "runner/experiment.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

using json = nlohmann::json;

/// Unit cubes on a lattice of 4 m cells, none overlapping: a ray that starts outside its agent's
/// bounding sphere starts outside every box.
std::vector<Object> sparse_cubes(int side) {
    std::vector<Object> objects;
    for (int i = 0; i < side * side * side; ++i) {
        const Vec3d min{4.0 * (i % side), 4.0 * ((i / side) % side), 4.0 * (i / (side * side))};
        objects.push_back({Uid(i), Aabb{min.as<float>(), (min + Vec3d{1, 1, 1}).as<float>()}});
    }
    return objects;
}

bool inside_some_box(const Vec3T<float>& p, const std::vector<Object>& objects) {
    for (const Object& o : objects)
        if (p.x >= o.box.min.x && p.x <= o.box.max.x && p.y >= o.box.min.y && p.y <= o.box.max.y &&
            p.z >= o.box.min.z && p.z <= o.box.max.z)
            return true;
    return false;
}

double length(const Segment& s) {
    const Vec3d d = s.p1.as<double>() - s.p0.as<double>();
    return std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
}

std::string file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(QueryPresets, EachRayCarriesItsModesKindAndStartsOutsideItsAgent) {
    const std::vector<Object> cubes = sparse_cubes(6);  // 216 cubes, bounds 21 m a side
    DynamicsSettings still;
    still.change_fraction = 0;
    RaySettings rays;
    rays.per_frame = 200;
    rays = with_query_preset(rays, "game");
    const Recording r = add_dynamics(cubes, still, rays, 3, 7, json::object());
    const double diagonal = std::sqrt(3.0) * 21;
    for (const Frame& f : r.frames) {
        ASSERT_EQ(f.rays.size(), 200u);
        ASSERT_EQ(f.kinds.size(), 200u);
        for (std::size_t i = 0; i < 200; ++i) {
            // 50% fire (closest), 30% sight (any), 20% sensor (all), in the mix's order.
            const QueryKind want = i < 100 ? QueryKind::closest : (i < 160 ? QueryKind::any : QueryKind::all);
            EXPECT_EQ(f.kinds[i], want) << i;
            EXPECT_FALSE(inside_some_box(f.rays[i].p0, cubes)) << i;
            if (i < 100) {
                EXPECT_NEAR(length(f.rays[i]), 0.25 * diagonal, 1e-3) << i;
            } else if (i < 160) {
                EXPECT_FALSE(inside_some_box(f.rays[i].p1, cubes)) << i;
            } else {
                EXPECT_NEAR(length(f.rays[i]), 3.0, 1e-4) << i;  // three longest edges
            }
        }
    }
    const json meta = json::parse(r.meta);
    EXPECT_EQ(meta["rays"]["queries"], "game");
    EXPECT_EQ(meta["rays"]["mix"][0], json({{"mode", "fire"}, {"weight", 0.5}, {"kind", "closest"}}));
    EXPECT_FALSE(meta["rays"].contains("query_mix"));
    const SceneWorkload w = scene_workload(r);
    EXPECT_DOUBLE_EQ(w.kind_share(QueryKind::closest), 0.5);
    EXPECT_DOUBLE_EQ(w.kind_share(QueryKind::any), 0.3);
    EXPECT_DOUBLE_EQ(w.kind_share(QueryKind::all), 0.2);
}

TEST(QueryPresets, SinglePresetsAskOneKind) {
    SceneSettings s;
    s.generator = "irregular";
    s.objects = 300;
    s.frames = 2;
    s.rays.per_frame = 40;
    const std::pair<const char*, QueryKind> presets[] = {
        {"shots", QueryKind::closest}, {"visibility", QueryKind::any}, {"sensors", QueryKind::all}};
    for (const auto& [name, kind] : presets) {
        s.rays = with_query_preset(s.rays, name);
        const Recording r = generate_scene(s);
        const SceneWorkload w = scene_workload(r);
        EXPECT_EQ(w.rays(), 80u) << name;
        EXPECT_DOUBLE_EQ(w.kind_share(kind), 1.0) << name;
        EXPECT_EQ(json::parse(r.meta)["rays"]["queries"], name);
    }
    test::expect_input_error([] { query_preset_mix("snipers"); }, "unknown query preset");
    RaySettings both = with_query_preset(RaySettings{}, "shots");
    both.query_mix = parse_query_mix("any");
    s.rays = both;
    test::expect_input_error([&] { generate_scene(s); }, "takes no query mix");
}

TEST(QueryPresets, SameSeedSameBytesAndScenesWithoutAPresetKeepTheirFormat) {
    const test::TempDir dir("presets");
    for (const char* generator : {"irregular", "brownian"}) {
        SceneSettings s;
        s.generator = generator;
        s.objects = 200;
        s.frames = 3;
        s.seed = 11;
        s.rays = with_query_preset(s.rays, "game");
        write_recording(generate_scene(s), dir.file("a.rcbscene"));
        write_recording(generate_scene(s), dir.file("b.rcbscene"));
        EXPECT_EQ(file_bytes(dir.file("a.rcbscene")), file_bytes(dir.file("b.rcbscene"))) << generator;
        s.seed = 12;
        write_recording(generate_scene(s), dir.file("b.rcbscene"));
        EXPECT_NE(file_bytes(dir.file("a.rcbscene")), file_bytes(dir.file("b.rcbscene"))) << generator;
        // Without a preset: no kinds, no kind in the mix, no preset in the meta (the older bytes).
        s.rays = RaySettings{};
        const Recording plain = generate_scene(s);
        for (const Frame& f : plain.frames) EXPECT_TRUE(f.kinds.empty());
        const json rays = json::parse(plain.meta)["rays"];
        EXPECT_EQ(rays, json({{"per_frame", 1000}, {"mix", json::array({{{"mode", "center"}, {"weight", 1.0}}})}}));
    }
}

TEST(QueryPresets, PhysicsScenesAndBroadmarkRaysCarryTheirKinds) {
    SceneSettings s;
    s.generator = "freefall";
    s.objects = 100;
    s.frames = 2;
    s.rays.per_frame = 30;
    s.rays.query_mix = parse_query_mix("closest:2,any:1");
    Recording r = generate_scene(s);
    EXPECT_NEAR(scene_workload(r).kind_share(QueryKind::closest), 2.0 / 3, 1e-9);
    EXPECT_TRUE(json::parse(r.meta)["rays"].contains("query_mix"));
    add_rays(r, with_query_preset(RaySettings{}, "visibility"), 3);
    EXPECT_DOUBLE_EQ(scene_workload(r).kind_share(QueryKind::any), 1.0);
}

TEST(QueryPresets, SceneGenAndInfoOnTheCommandLine) {
    const std::string bin = RCBENCH_BINARY;
    const test::TempDir dir("presets");
    const std::string file = dir.file("g.rcbscene");
    const ::test::Outcome gen = ::test::run_shell(
        bin + " scene gen --generator pile --objects 200 --frames 3 --rays 100 " + "--queries game -o " + file);
    ASSERT_EQ(gen.code, 0) << gen.err;
    const ::test::Outcome info = ::test::run_shell(bin + " scene info --json " + file);
    ASSERT_EQ(info.code, 0) << info.err;
    const json j = json::parse(info.out);
    EXPECT_EQ(j["query_kinds"], json({{"all", 60}, {"closest", 150}, {"any", 90}}));
    EXPECT_EQ(j["meta"]["rays"]["queries"], "game");
    const ::test::Outcome table = ::test::run_shell(bin + " scene info " + file);
    EXPECT_NE(table.out.find("query preset"), std::string::npos) << table.out;
    EXPECT_NE(table.out.find("closest 50.0%, any 30.0%, all 20.0%"), std::string::npos) << table.out;
    for (const char* bad : {"--queries game --ray-mix los", "--queries game --query-mix any", "--queries snipers"}) {
        const ::test::Outcome o = ::test::run_shell(bin + " scene gen --generator uniform --objects 10 " + bad +
                                                    " -o " + dir.file("x.rcbscene"));
        EXPECT_EQ(o.code, 2) << bad << ": " << o.err;
        EXPECT_NE(o.err.find("--queries"), std::string::npos) << o.err;
    }
    EXPECT_FALSE(std::filesystem::exists(dir.file("x.rcbscene")));
}

std::string experiment_error(const std::string& scene) {
    return test::input_error_of([&] {
        parse_experiment(R"({"scenes": [)" + scene + R"(], "structures": [{"name": "bf"}]})", "exp.json", ".");
    });
}

TEST(QueryPresets, ExperimentEntriesTakePresetsPhysicsKindsAndTimeSteps) {
    const Experiment e = parse_experiment(
        R"({"scenes": [{"generator": "brownian", "objects": 100, "queries": "game", "time_step": 0.01},
                       {"generator": "pile", "objects": 100, "query_mix": "closest"},
                       {"generator": "uniform", "objects": 100}],
            "structures": [{"name": "bf"}]})",
        "exp.json", ".");
    ASSERT_EQ(e.scenes.size(), 3u);
    EXPECT_EQ(e.scenes[0].settings.rays.queries, "game");
    EXPECT_EQ(e.scenes[0].settings.time_step, 0.01);
    EXPECT_EQ(e.scenes[0].key["queries"], "game");
    EXPECT_EQ(e.scenes[0].key["time_step"], 0.01);
    EXPECT_EQ(e.scenes[0].key["ray_mix"], "fire:0.5,sight:0.3,sensor:0.2");
    EXPECT_FALSE(e.scenes[1].key.contains("time_step"));  // the default keeps older keys
    EXPECT_FALSE(e.scenes[2].key.contains("queries"));
    EXPECT_EQ(experiment_error(R"({"generator": "pile", "objects": 10, "queries": "x"})"),
              "exp.json: scenes[0].queries: unknown query preset 'x' (known: shots, visibility, sensors, game)");
    EXPECT_EQ(experiment_error(R"({"generator": "pile", "objects": 10, "queries": "game", "ray_mix": "los"})"),
              "exp.json: scenes[0].ray_mix: a query preset (\"queries\") sets the ray modes and their kinds");
    EXPECT_EQ(experiment_error(R"({"generator": "uniform", "objects": 10, "time_step": 0.01})"),
              "exp.json: scenes[0].time_step: only a physics generator (pile, collapse, explosion, brownian, freefall, "
              "gravity) takes a time step");
    EXPECT_EQ(experiment_error(R"({"generator": "pile", "objects": 10, "time_step": 1})")
                  .find("exp.json: scenes[0].time_step: expected a number in"),
              0u);
    EXPECT_EQ(experiment_error(R"({"generator": "pile", "objects": 10, "change_fraction": 0.1})"),
              "exp.json: scenes[0].change_fraction: a physics generator (pile) moves by its simulation, not by "
              "change_fraction");
    EXPECT_EQ(experiment_error(R"({"preset": "uni-s", "queries": "game", "seeds": [1]}, {"preset": "uni-s"})"), "");
}

}  // namespace
}  // namespace rcb

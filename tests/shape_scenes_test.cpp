// Generated scenes with shapes (generators.h ShapeSettings): deterministic by seed, the requested
// kinds in the requested shares, boxes that are their shapes' bounds, moves that keep an object's
// kind and rotation, invalid shares rejected everywhere they enter, and every structure at the
// shapes level matching the ground truth on them.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"
#include "runner/experiment.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

SceneSettings shaped_settings(const char* preset, std::uint64_t seed = 1) {
    SceneSettings s = preset_settings(preset);
    s.seed = seed;
    s.frames = 4;
    s.rays.per_frame = 100;
    s.dynamics.change_fraction = 0.05;
    s.shapes = {0.5, 0.2, 0.2};
    return s;
}

std::array<std::size_t, kShapeKinds> kind_counts(const std::vector<Object>& objects) {
    std::array<std::size_t, kShapeKinds> n{};
    for (const Object& o : objects) ++n[int(o.shape.kind)];
    return n;
}

/// `inner` within `outer`, allowing a float step of slack for the outward rounding of bounds.
bool nearly_within(const Aabb& inner, const Aabb& outer) {
    for (int a = 0; a < 3; ++a) {
        const float slack = 4 * std::numeric_limits<float>::epsilon() *
                            std::max({1.0f, std::abs(outer.min[a]), std::abs(outer.max[a])});
        if (inner.min[a] < outer.min[a] - slack || inner.max[a] > outer.max[a] + slack) return false;
    }
    return true;
}

TEST(ShapeScenes, ZeroSharesKeepTheBytesOfBoxScenes) {
    // stable_hash of `rcbench scene gen --preset P --frames 5 --rays 200 --change-fraction 0.05`,
    // as written before generated scenes had shapes.
    for (const auto& [preset, hash] : {std::pair{"uni-m", "db09115e3c96abe5"}, {"irreg-m", "d7f2f88cc375697d"}}) {
        SceneSettings s = preset_settings(preset);
        s.frames = 5;
        s.rays.per_frame = 200;
        s.dynamics.change_fraction = 0.05;
        const Recording r = generate_scene(s);
        EXPECT_EQ(recording_version(r), 1u) << preset;
        EXPECT_EQ(stable_hash(encode_recording(r)), hash) << preset;
    }
}

TEST(ShapeScenes, SameSeedSameBytesOtherSeedOtherScene) {
    for (const char* preset : {"uni-m", "irreg-m", "clusters-m"}) {
        const std::string a = encode_recording(generate_scene(shaped_settings(preset)));
        EXPECT_EQ(a, encode_recording(generate_scene(shaped_settings(preset)))) << preset;
        EXPECT_NE(a, encode_recording(generate_scene(shaped_settings(preset, 2)))) << preset;
    }
}

TEST(ShapeScenes, SharesGiveTheRequestedKindsInsideTheGeneratedBoxes) {
    SceneSettings s = shaped_settings("irreg-m");
    s.shapes = {0.3, 0.25, 0.15};
    const std::vector<Object> objects = generate_objects(s);
    SceneSettings plain = s;
    plain.shapes = {};
    const std::vector<Object> boxes = generate_objects(plain);
    ASSERT_EQ(objects.size(), boxes.size());
    const auto n = kind_counts(objects);
    const double total = double(objects.size());
    EXPECT_EQ(n[int(ShapeKind::obb)], std::size_t(std::llround(0.3 * total)));
    EXPECT_EQ(n[int(ShapeKind::sphere)], std::size_t(std::llround(0.25 * total)));
    EXPECT_EQ(n[int(ShapeKind::capsule)], std::size_t(std::llround(0.15 * total)));
    EXPECT_EQ(n[int(ShapeKind::triangle)], 0u);
    for (std::size_t i = 0; i < objects.size(); ++i) {
        const Object& o = objects[i];
        const Aabb& generated = boxes[i].box;
        ASSERT_EQ(o.uid, boxes[i].uid);
        if (o.shape.kind == ShapeKind::box) {
            EXPECT_EQ(o, boxes[i]);
            continue;
        }
        EXPECT_EQ(o.box, shape_bounds(o.shape));
        EXPECT_EQ(shape_problem(o.shape, kMaxCoordinate), "");
        if (o.shape.kind == ShapeKind::obb) {
            // The generated box's centre and half extents, rotated: its bounds hold the box's volume.
            const Vec3 c = generated.center(), h = generated.extent() * 0.5f;
            for (int a = 0; a < 3; ++a) {
                EXPECT_NEAR(o.shape.v[a], c[a], 1e-5 * std::max(1.0f, std::abs(c[a])));
                EXPECT_NEAR(o.shape.v[3 + a], h[a], 1e-5 * std::max(1.0f, h[a]));
            }
        } else {
            EXPECT_TRUE(nearly_within(o.box, generated)) << "uid " << o.uid << " " << shape_name(o.shape.kind);
        }
    }
}

TEST(ShapeScenes, MovesKeepKindAndRotationAndInsertsCopyShapes) {
    const Recording r = generate_scene(shaped_settings("uni-m"));
    EXPECT_EQ(recording_version(r), 2u);
    LiveSet live(r.initial);
    std::size_t shaped_moves = 0, shaped_inserts = 0;
    for (const Frame& f : r.frames) {
        for (const Object& m : f.moves) {
            ASSERT_TRUE(live.contains(m.uid));
            const Object& before = live.object(m.uid);
            ASSERT_EQ(m.shape.kind, before.shape.kind);
            EXPECT_EQ(m.box, m.shape.kind == ShapeKind::box ? m.box : shape_bounds(m.shape));
            switch (m.shape.kind) {
                case ShapeKind::obb:
                    for (int i = 3; i < 10; ++i) EXPECT_EQ(m.shape.v[i], before.shape.v[i]);  // extents, rotation
                    break;
                case ShapeKind::sphere:
                    EXPECT_EQ(m.shape.v[3], before.shape.v[3]);
                    break;
                case ShapeKind::capsule: {
                    EXPECT_EQ(m.shape.v[6], before.shape.v[6]);
                    // Translated: the axis keeps its direction and length (up to float rounding).
                    for (int a = 0; a < 3; ++a)
                        EXPECT_NEAR(m.shape.v[3 + a] - m.shape.v[a], before.shape.v[3 + a] - before.shape.v[a], 1e-3);
                    break;
                }
                default:
                    break;
            }
            shaped_moves += m.shape.kind != ShapeKind::box;
        }
        for (const Object& o : f.inserts) {
            if (o.shape.kind == ShapeKind::box) continue;
            ++shaped_inserts;
            EXPECT_EQ(o.box, shape_bounds(o.shape));
        }
        live.apply(f);
    }
    EXPECT_GT(shaped_moves, 0u);
    EXPECT_GT(shaped_inserts, 0u);
    // The file reads back as written.
    EXPECT_EQ(decode_recording(encode_recording(r), "r"), r);
}

TEST(ShapeScenes, InvalidSharesAreRejectedNamingTheSetting) {
    auto message = [](ShapeSettings shapes) -> std::string {
        SceneSettings s = preset_settings("uni-s");
        s.shapes = shapes;
        return test::input_error_of([&] { generate_scene(s); });
    };
    const double nan = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(message({-0.1, 0, 0}).rfind("rotated_share: expected a number in 0..1", 0), 0u);
    EXPECT_EQ(message({0, 1.5, 0}).rfind("sphere_share: expected a number in 0..1", 0), 0u);
    EXPECT_EQ(message({0, 0, nan}).rfind("capsule_share: expected a number in 0..1", 0), 0u);
    EXPECT_EQ(message({0.5, 0.3, 0.3}), "rotated_share + sphere_share + capsule_share exceeds 1");
    EXPECT_EQ(message({0.5, 0.25, 0.25}), "");  // exactly 1 is fine

    // In an experiment's scene spec: the JSON path and the setting.
    auto spec_error = [](const std::string& scene) {
        return test::input_error_of(
            [&] { parse_scenes(nlohmann::json::parse("[" + scene + "]"), "scenes", SceneDefaults{}, "."); });
    };
    EXPECT_NE(spec_error(R"({"preset": "uni-s", "rotated_share": 2})").find("rotated_share"), std::string::npos);
    EXPECT_NE(spec_error(R"({"preset": "uni-s", "sphere_share": "half"})").find("sphere_share"), std::string::npos);
    EXPECT_NE(spec_error(R"({"preset": "uni-s", "sphere_share": 0.6, "capsule_share": 0.6})").find("exceeds 1"),
              std::string::npos);
    EXPECT_EQ(spec_error(R"({"preset": "uni-s", "rotated_share": 0.5, "capsule_share": 0.1})"), "");

    // On the command line: exit 2, one line naming the option.
    for (const char* args : {"--rotated-share nan", "--sphere-share 1.5", "--capsule-share -1",
                             "--rotated-share 0.7 --sphere-share 0.7"}) {
        const ::test::Outcome r = ::test::run_shell(std::string(RCBENCH_BINARY) + " scene gen --preset uni-s " + args +
                                                    " -o /dev/null/never.rcbscene");
        EXPECT_EQ(r.code, 2) << args << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_TRUE(r.err.find("share") != std::string::npos) << r.err;
    }
}

TEST(ShapeScenes, SceneInfoShowsTheVersionAndTheKinds) {
    const std::string dir = ::testing::TempDir();
    const std::string shaped = dir + "/rcb_shape_scenes_info.rcbscene",
                      plain = dir + "/rcb_shape_scenes_plain.rcbscene";
    const std::string bin = RCBENCH_BINARY;
    ASSERT_EQ(::test::run_shell(bin +
                                " scene gen --preset uni-s --frames 2 --rotated-share 0.5 --sphere-share 0.2 "
                                "--capsule-share 0.1 -o " +
                                shaped)
                  .code,
              0);
    ASSERT_EQ(::test::run_shell(bin + " scene gen --preset uni-s --frames 2 -o " + plain).code, 0);
    const ::test::Outcome info = ::test::run_shell(bin + " scene info --json " + shaped);
    ASSERT_EQ(info.code, 0) << info.err;
    const auto j = nlohmann::json::parse(info.out);
    EXPECT_EQ(j["version"], 2);
    EXPECT_EQ(j["shapes"]["obb"], 50);  // round(0.5 x 99)
    EXPECT_EQ(j["shapes"]["sphere"], 20);
    EXPECT_EQ(j["shapes"]["capsule"], 10);
    EXPECT_EQ(j["shapes"]["box"], 19);
    EXPECT_EQ(j["shapes"]["triangle"], 0);
    EXPECT_EQ(j["meta"]["shapes"]["rotated_share"], 0.5);
    const ::test::Outcome table = ::test::run_shell(bin + " scene info " + shaped);
    EXPECT_NE(table.out.find("box 19, obb 50, sphere 20, capsule 10"), std::string::npos) << table.out;
    const auto p = nlohmann::json::parse(::test::run_shell(bin + " scene info --json " + plain).out);
    EXPECT_EQ(p["version"], 1);
    EXPECT_EQ(p["shapes"]["box"], 99);
    EXPECT_FALSE(p["meta"].contains("shapes"));
}

TEST(ShapeScenes, ExperimentKeysNameShapesOnlyWhenSet) {
    const std::vector<SceneSpec> specs =
        parse_scenes(nlohmann::json::parse(
                         R"([{"preset": "uni-s"}, {"preset": "uni-s", "rotated_share": 0.5, "sphere_share": 0.25}])"),
                     "scenes", SceneDefaults{}, ".");
    ASSERT_EQ(specs.size(), 2u);
    EXPECT_FALSE(specs[0].key.contains("shapes"));
    EXPECT_EQ(specs[1].key["shapes"]["rotated_share"], 0.5);
    EXPECT_EQ(specs[1].settings.shapes.sphere_share, 0.25);
    EXPECT_NE(specs[0].key, specs[1].key);
}

TEST(ShapeScenes, EveryStructureMatchesTheGroundTruthOnGeneratedShapes) {
    // The thesis' small scenes, and failure modes whose shapes are degenerate: zero-thickness
    // oriented boxes and zero-radius spheres ("flat"), needles and points ("slivers"), a huge
    // rotated box around a tiny cluster ("stadium").
    for (const char* preset : {"uni-s", "irreg-s", "flat-s", "slivers-s", "stadium-s"}) {
        SceneSettings s = preset_settings(preset);
        s.objects = std::min<std::uint32_t>(s.objects, 300);
        s.frames = 3;
        s.rays.per_frame = 200;
        s.rays.mix = parse_ray_mix("center,los,shots,inside");
        s.dynamics.change_fraction = 0.1;
        s.shapes = {0.4, 0.2, 0.2};
        const Recording r = generate_scene(s);
        for (const StructureInfo& info : structure_registry()) {
            SCOPED_TRACE(std::string(preset) + " / " + info.name);
            const SimulationResult shapes = test::expect_matches_ground_truth(r, info.name, {{"query", "shapes"}});
            for (const FrameResult& f : shapes.frames) {
                EXPECT_EQ(f.precision(), 1.0);
                EXPECT_EQ(f.recall(), 1.0);
            }
        }
    }
}

}  // namespace
}  // namespace rcb

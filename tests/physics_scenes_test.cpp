// Physics-driven scenes (core/scene/generate/physics.h): the same seed gives the same bytes for
// every generator, each one's motion has the character it is named for (within stated bounds), the
// objects' shapes carry the bodies' rotations, bad settings are refused, and every structure
// matches the ground truth on them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "accel/registry.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/generate/physics.h"
#include "core/scene/phases.h"
#include "core/scene/recording_io.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

SceneSettings physics(const std::string& generator, std::uint32_t objects, std::uint32_t frames,
                      std::uint64_t seed = 1) {
    SceneSettings s;
    s.generator = generator;
    s.objects = objects;
    s.frames = frames;
    s.seed = seed;
    s.rays.per_frame = 50;
    if (!is_broadmark_generator(generator)) s.shapes = {0.25, 0.2, 0.2};  // Broadmark's generators take a shape set
    return s;
}

SceneSettings broadmark(const std::string& generator, const std::string& set, std::uint32_t objects,
                        std::uint32_t frames) {
    SceneSettings s = physics(generator, objects, frames);
    s.shape_set = set;
    s.rays.per_frame = 0;
    return s;
}

/// The share of the live objects each frame moves.
std::vector<double> moved_shares(const Recording& r) {
    std::vector<double> shares;
    for (const Frame& f : r.frames) shares.push_back(double(f.moves.size()) / double(r.initial.size()));
    return shares;
}

/// The objects after the last frame.
std::vector<Object> final_objects(const Recording& r) {
    LiveSet live(r.initial);
    for (const Frame& f : r.frames) live.apply(f);
    std::vector<Object> objects = live.objects();
    std::sort(objects.begin(), objects.end(), [](const Object& a, const Object& b) { return a.uid < b.uid; });
    return objects;
}

double mean_height(const std::vector<Object>& objects) {
    double sum = 0;
    for (const Object& o : objects) sum += o.box.as<double>().center().y;
    return sum / double(objects.size());
}

TEST(PhysicsScenes, EveryKindIsDeterministicForASeed) {
    for (const std::string& generator : physics_generators()) {
        SCOPED_TRACE(generator);
        const std::string a = encode_recording(generate_scene(physics(generator, 150, 12)));
        EXPECT_EQ(a, encode_recording(generate_scene(physics(generator, 150, 12))));
        EXPECT_NE(a, encode_recording(generate_scene(physics(generator, 150, 12, 2))));
        const Recording r = decode_recording(a, generator);  // the reader's checks: shapes valid, boxes their bounds
        EXPECT_EQ(r.initial.size(), 150u);
        EXPECT_EQ(r.frames.size(), 12u);
        for (const Frame& f : r.frames) {
            EXPECT_TRUE(f.inserts.empty() && f.removes.empty());
            EXPECT_EQ(f.rays.size(), 50u);
        }
        EXPECT_EQ(nlohmann::json::parse(r.meta)["kind"], generator);
    }
}

TEST(PhysicsScenes, ShapeSharesAndRotationsAreKept) {
    const Recording r = generate_scene(physics("explosion", 200, 60));
    std::array<int, kShapeKinds> kinds{};
    for (const Object& o : r.initial) ++kinds[int(o.shape.kind)];
    EXPECT_EQ(kinds[int(ShapeKind::obb)], 50);  // round(0.25 x 200) rotated
    EXPECT_EQ(kinds[int(ShapeKind::sphere)], 40);
    EXPECT_EQ(kinds[int(ShapeKind::capsule)], 40);
    EXPECT_EQ(kinds[int(ShapeKind::box)], 70);
    // Flung bodies spin: axis-aligned boxes become oriented boxes, and every box is its shape's bounds.
    std::size_t turned = 0;
    for (const Object& o : final_objects(r)) {
        if (o.shape.kind != ShapeKind::box) {
            EXPECT_EQ(o.box, shape_bounds(o.shape));
        }
        turned += o.shape.kind == ShapeKind::obb;
    }
    EXPECT_GT(turned, 50u);
}

TEST(PhysicsScenes, PileSettlesAndFallsAsleep) {
    // 10 s: the bodies land and settle, then sleep after Bullet's 2 s below its thresholds.
    // (Piles mixing capsules with the other shapes take longer to come to rest.)
    SceneSettings s = physics("pile", 200, 600);
    s.shapes = {0.3, 0.3, 0};
    const std::vector<double> shares = moved_shares(generate_scene(s));
    EXPECT_GT(shares.front(), 0.95);  // everything falls at first
    EXPECT_LT(shares.back(), 0.1);
}

TEST(PhysicsScenes, LargePilesFallAsleep) {
    // A settled pile is one island of nearly all its bodies (physics.cpp, kLinearSleep): 400 boxes,
    // and 400 bodies of mixed shapes, move in under 10% per frame through the whole last 3 s of a
    // 15 s recording, and in under 1% at its end; the same seed gives the same bytes. (Under
    // Bullet's default sleeping rule over 90% of them moved in every frame.)
    for (const ShapeSettings& shapes : {ShapeSettings{}, ShapeSettings{0.25, 0.2, 0.2}}) {
        SCOPED_TRACE(shapes.sphere_share);
        SceneSettings s = physics("pile", 400, 900);
        s.shapes = shapes;
        s.rays.per_frame = 5;
        const Recording r = generate_scene(s);
        EXPECT_EQ(encode_recording(r), encode_recording(generate_scene(s)));
        const std::vector<double> shares = moved_shares(r);
        EXPECT_GT(shares.front(), 0.95);
        for (std::size_t f = 720; f < shares.size(); ++f) ASSERT_LT(shares[f], 0.1) << "frame " << f + 1;
        EXPECT_LT(shares.back(), 0.01);
    }
}

TEST(PhysicsScenes, PileOnAMapLandsOnItsBoxes) {
    // A floor 40 x 40 m with its top at y = 0, a block 6 m tall on it and a post 12 m tall in a
    // corner (so the map's bounds reach above the block); 5 s after the drop.
    const std::vector<Aabb> map{Aabb{{0, -1, 0}, {40, 0, 40}}, Aabb{{10, 0, 10}, {20, 6, 20}},
                                Aabb{{38, 0, 38}, {40, 12, 40}}};
    const SceneSettings s = physics("pile", 150, 300);
    const Recording r = generate_physics_scene(s, map);
    EXPECT_EQ(encode_recording(r), encode_recording(generate_physics_scene(s, map)));
    ASSERT_EQ(r.initial.size(), 153u);
    for (std::size_t i = 0; i < map.size(); ++i) EXPECT_EQ(r.initial[150 + i], (Object{Uid(150 + i), map[i]}));
    EXPECT_EQ(nlohmann::json::parse(r.meta)["map_boxes"], 3);
    for (const Frame& f : r.frames)
        for (const Object& o : f.moves) ASSERT_LT(o.uid, 150u);  // the map never moves
    const std::vector<Object> start = r.initial, end = final_objects(r);
    // Each body starts in free space and ends on the map's boxes, or (tumbling off the floor's
    // edge) on the plane under the map's lowest point, never inside a box.
    std::size_t on_block = 0, off_edge = 0;
    for (std::size_t i = 0; i < 150; ++i) {
        for (const Aabb& b : map) EXPECT_FALSE(start[i].box.overlaps(b)) << i;
        const Aabb e = end[i].box;
        const bool on_floor = e.min.y > -0.05f, on_plane = e.min.y > -1.05f && e.max.y < 0.5f &&
                                                           (e.min.x < 0 || e.max.x > 40 || e.min.z < 0 || e.max.z > 40);
        EXPECT_TRUE(on_floor || on_plane) << i << ": " << e.min.y;
        off_edge += !on_floor;
        const Vec3 c = e.center();
        on_block += c.x > 10 && c.x < 20 && c.z > 10 && c.z < 20 && e.min.y > 5.9f;
    }
    EXPECT_GT(on_block, 0u);
    EXPECT_LE(off_edge, 8u);
    // A map without room for the bodies, and a generator that is not a pile, are refused.
    const std::vector<Aabb> slab{Aabb{{0, -1, 0}, {4, 0, 4}}};
    test::expect_input_error([&] { generate_physics_scene(physics("pile", 10, 1), slab); },
                             "the map has room for 0 of 10 bodies");
    test::expect_input_error([&] { generate_physics_scene(physics("freefall", 10, 1), map); },
                             "only the pile generator is dropped onto a map, not freefall");
}

TEST(PhysicsScenes, BrownianAndGravityMoveEveryBodyEveryFrame) {
    // Gravity's bodies never sleep; a brownian body that collisions slowed below the sleeping
    // thresholds rests until its next kick, a few of 200.
    for (const char* generator : {"brownian", "gravity"}) {
        SCOPED_TRACE(generator);
        const double least = std::string(generator) == "gravity" ? 0.99 : 0.95;
        for (double share : moved_shares(generate_scene(physics(generator, 200, 40)))) EXPECT_GE(share, least);
    }
}

double mean_x(const std::vector<Object>& objects) {
    double sum = 0;
    for (const Object& o : objects) sum += o.box.as<double>().center().x;
    return sum / double(objects.size());
}

TEST(PhysicsScenes, BroadmarkScenesFollowItsGenerator) {
    // Broadmark's parameters (physics.cpp cites SimulationGenerator/Assets/Scripts): 500 unit cubes
    // fill 0.1 of an arena of side L = (500 / 0.1)^(1/3), spawned in a ball of radius 0.45 L, at
    // most 0.75 L/s, one frame 1/30 s; no body leaves the closed arena in 90 frames (3 s).
    for (const char* generator : {"brownian", "freefall", "gravity"}) {
        SCOPED_TRACE(generator);
        const Recording r = generate_scene(broadmark(generator, "cubes", 500, 90));
        const auto meta = nlohmann::json::parse(r.meta);
        const double side = std::cbrt(500 / 0.1), dt = 1.0 / 30;
        EXPECT_DOUBLE_EQ(meta["arena"].get<double>(), side);
        EXPECT_DOUBLE_EQ(meta["time_step"].get<double>(), dt);
        EXPECT_EQ(meta["shape_set"], "cubes");
        double volume = 0, widest = 0;
        for (const Object& o : r.initial) {
            const Aabbd b = o.box.as<double>();
            volume += b.extent().x * b.extent().y * b.extent().z;
            const Vec3d c = b.center();
            widest = std::max(widest, std::sqrt(c.x * c.x + c.y * c.y + c.z * c.z));
        }
        EXPECT_NEAR(volume / (side * side * side), 0.1, 1e-5);
        EXPECT_LE(widest, 0.45 * side + 1e-4);
        EXPECT_GT(widest, 0.4 * side);  // the ball, not a smaller one
        LiveSet live(r.initial);
        double fastest = 0;
        for (std::size_t f = 0; f < r.frames.size(); ++f) {
            for (const Object& o : r.frames[f].moves) {
                const Vec3d a = live.box(o.uid).as<double>().center(), c = o.box.as<double>().center();
                const Vec3d d = c - a;
                if (f > 0) fastest = std::max(fastest, std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z) / dt);
                ASSERT_TRUE(std::abs(c.x) <= side / 2 && std::abs(c.y) <= side / 2 && std::abs(c.z) <= side / 2)
                    << "frame " << f + 1 << " uid " << o.uid << " left the arena";
            }
            live.apply(r.frames[f]);
        }
        EXPECT_LT(fastest, 1.5 * 0.75 * side) << "speeds beyond 0.75 L/s by more than collisions add";
    }
    // Freefall falls (0.0981 L/s² down) and gravity's pull starts along +x (0.3924 L/s²): after
    // 0.5 s their bodies' mean lies 0.012 L lower and 0.049 L further along x than brownian's, which
    // spawns the same bodies with the same velocities (the same seed) without gravity.
    const double side = std::cbrt(500 / 0.1);
    const std::vector<Object> still = final_objects(generate_scene(broadmark("brownian", "cubes", 500, 15)));
    const std::vector<Object> fell = final_objects(generate_scene(broadmark("freefall", "cubes", 500, 15)));
    const std::vector<Object> pulled = final_objects(generate_scene(broadmark("gravity", "cubes", 500, 15)));
    EXPECT_NEAR(mean_height(fell) - mean_height(still), -0.0123 * side, 0.004 * side);
    EXPECT_NEAR(mean_x(fell) - mean_x(still), 0, 0.004 * side);
    EXPECT_NEAR(mean_x(pulled) - mean_x(still), 0.049 * side, 0.01 * side);
    EXPECT_NEAR(mean_height(pulled) - mean_height(still), 0, 0.01 * side);
}

TEST(PhysicsScenes, BroadmarkShapeSets) {
    // Spheres of diameter 1; the Assorted set by body index mod 80 (Simulation.cs,
    // GenerateAssortedSize): cubes, bars and slabs of 38:1, planks of 57:1 and 19:1, and random
    // boxes of 0.803 x 0.1..1.9 per axis. Frame 0 is axis-aligned, so each box is the body.
    const Recording sp = generate_scene(broadmark("brownian", "spheres", 160, 2));
    for (const Object& o : sp.initial) {
        ASSERT_EQ(o.shape.kind, ShapeKind::sphere);
        EXPECT_NEAR(o.box.as<double>().extent().x, 1.0, 1e-5);
    }
    const Recording as = generate_scene(broadmark("freefall", "assorted", 160, 2));
    EXPECT_EQ(nlohmann::json::parse(as.meta)["shape_set"], "assorted");
    for (const Object& o : as.initial) {
        const Vec3d e = o.box.as<double>().extent();
        const double longest = std::max({e.x, e.y, e.z}), shortest = std::min({e.x, e.y, e.z});
        const std::size_t k = o.uid % 80;
        SCOPED_TRACE(k);
        // The expected aspect ratio by index (0 for the random boxes, bounded per edge instead).
        const double ratio = k < 8 ? 1 : k < 13 ? 38 : k < 15 ? 57 : k < 16 ? 19 : k < 19 ? 38 : 0;
        if (ratio > 0) {
            EXPECT_NEAR(longest / shortest, ratio, 1e-3);
        } else {
            EXPECT_TRUE(shortest >= 0.0803 - 1e-4 && longest <= 1.5257 + 1e-4) << shortest << " " << longest;
        }
    }
    // The same seed gives the same bytes for every set; another seed other bytes.
    for (const char* set : {"cubes", "spheres", "assorted"}) {
        SCOPED_TRACE(set);
        const std::string a = encode_recording(generate_scene(broadmark("gravity", set, 120, 6)));
        EXPECT_EQ(a, encode_recording(generate_scene(broadmark("gravity", set, 120, 6))));
        SceneSettings other = broadmark("gravity", set, 120, 6);
        other.seed = 2;
        EXPECT_NE(a, encode_recording(generate_scene(other)));
    }
}

TEST(PhysicsScenes, FreefallSettlesOnTheArenaFloor) {
    // 10 s under 0.0981 L/s²: the bodies lie in the lower part of the arena and most are asleep.
    const Recording r = generate_scene(broadmark("freefall", "cubes", 300, 300));
    const double side = std::cbrt(300 / 0.1);
    EXPECT_LT(mean_height(final_objects(r)), -0.3 * side);
    EXPECT_LT(moved_shares(r).back(), 0.2);
}

TEST(PhysicsScenes, ExplosionScattersAndCollapseKnocksWallsOver) {
    // Explosion: 1 s at 10 to 20 m/s outward from a ball 12 m across.
    const Recording e = generate_scene(physics("explosion", 300, 60));
    const double before = bounds_of(e.initial).longest_edge(), after = bounds_of(final_objects(e)).longest_edge();
    EXPECT_GT(after, 2.5 * before);
    // Collapse: 2 walls of 100 bricks and a ball each; after 2 s the balls have punched through the
    // lower rows and bricks above have come down (over 0.5 m lower).
    SceneSettings c = physics("collapse", 202, 120);
    c.shapes = {};
    const Recording r = generate_scene(c);
    const std::vector<Object> end = final_objects(r);
    std::size_t fallen = 0;
    for (std::size_t i = 0; i < end.size(); ++i)
        fallen += end[i].box.as<double>().center().y < r.initial[i].box.as<double>().center().y - 0.5;
    EXPECT_GE(fallen, 8u);
}

TEST(PhysicsScenes, BadSettingsAreRefused) {
    SceneSettings b = broadmark("brownian", "cubes", 10, 2);
    b.shapes = {0, 0.5, 0};
    test::expect_input_error([&] { generate_scene(b); }, "shapes: brownian is Broadmark's scene");
    b = broadmark("brownian", "cones", 10, 2);
    test::expect_input_error([&] { generate_scene(b); }, "shape_set: unknown set 'cones'");
    b = broadmark("brownian", "", 10, 2);
    b.fill = 0.9;
    test::expect_input_error([&] { generate_scene(b); }, "fill: expected a share of the arena in (0, 0.5]");
    b = physics("pile", 10, 2);
    b.shape_set = "cubes";
    test::expect_input_error([&] { generate_scene(b); }, "shape_set: only Broadmark's generators");
    SceneSettings s = physics("pile", 10, 2);
    s.time_step = -0.01;  // 0 takes the generator's default
    test::expect_input_error([&] { generate_scene(s); }, "time_step");
    s.time_step = std::nan("");
    test::expect_input_error([&] { generate_scene(s); }, "time_step");
    s = physics("pile", 10, 2);
    s.shapes = {0.8, 0.5, 0};
    test::expect_input_error([&] { generate_scene(s); }, "exceeds 1");
    const std::string bin = RCBENCH_BINARY;
    const test::TempDir dir("physics");
    for (const char* bad : {"--time-step 0", "--time-step 1", "--time-step nan"}) {
        const ::test::Outcome o = ::test::run_shell(bin + " scene gen --generator pile --objects 10 " + bad + " -o " +
                                                    dir.file("x.rcbscene"));
        EXPECT_EQ(o.code, 2) << bad << ": " << o.err;
        EXPECT_NE(o.err.find("--time-step"), std::string::npos) << o.err;
    }
    for (const char* bad : {"--generator brownian --shape-set cones", "--generator gravity --fill 0.9",
                            "--generator pile --shape-set cubes", "--generator freefall --sphere-share 0.5"}) {
        const ::test::Outcome o =
            ::test::run_shell(bin + " scene gen --objects 10 " + std::string(bad) + " -o " + dir.file("x.rcbscene"));
        EXPECT_EQ(o.code, 2) << bad << ": " << o.err;
    }
    EXPECT_FALSE(std::filesystem::exists(dir.file("x.rcbscene")));
}

TEST(PhysicsScenes, ExperimentEntriesTakeShapeSetAndFill) {
    const Experiment e = parse_experiment(
        R"({"scenes": [{"generator": "gravity", "objects": 100, "shape_set": "assorted", "fill": 0.01},
                       {"generator": "freefall", "objects": 100}],
            "structures": [{"name": "bf"}]})",
        "exp.json", ".");
    ASSERT_EQ(e.scenes.size(), 2u);
    EXPECT_EQ(e.scenes[0].settings.shape_set, "assorted");
    EXPECT_EQ(e.scenes[0].settings.fill, 0.01);
    EXPECT_EQ(e.scenes[0].key["shape_set"], "assorted");
    EXPECT_EQ(e.scenes[0].key["fill"], 0.01);
    EXPECT_FALSE(e.scenes[1].key.contains("shape_set"));  // older keys stay as they were
    EXPECT_FALSE(e.scenes[1].key.contains("fill"));
    const auto error = [](const std::string& scene) {
        return test::input_error_of([&] {
            parse_experiment(R"({"scenes": [)" + scene + R"(], "structures": [{"name": "bf"}]})", "exp.json", ".");
        });
    };
    EXPECT_EQ(
        error(R"({"generator": "pile", "objects": 10, "shape_set": "cubes"})"),
        "exp.json: scenes[0].shape_set: only Broadmark's generators (brownian, freefall, gravity) take shape_set");
    EXPECT_EQ(error(R"({"generator": "brownian", "objects": 10, "shape_set": "cones"})"),
              "exp.json: scenes[0].shape_set: unknown set 'cones' (known: cubes, spheres, assorted)");
    EXPECT_NE(
        error(R"({"generator": "brownian", "objects": 10, "fill": 2})").find("exp.json: scenes[0].fill: expected"),
        std::string::npos);
}

TEST(PhysicsScenes, MotionPhasesSplitTheFrames) {
    // A pile of 200 over 10 s: it falls, lands, settles and sleeps; the phases cover every frame
    // once, in order, and sleeping bodies are no changes (the asleep phase moves under 10%).
    SceneSettings s = physics("pile", 200, 600);
    s.shapes = {0.3, 0.3, 0};
    s.rays.per_frame = 0;
    const Recording r = generate_scene(s);
    const std::vector<MotionPhase> phases = motion_phases(r);
    ASSERT_EQ(phases.size(), 4u);
    std::uint32_t next = 1;
    for (std::size_t i = 0; i < phases.size(); ++i) {
        EXPECT_EQ(phases[i].name, motion_phase_names()[i]);
        EXPECT_EQ(phases[i].first, next) << phases[i].name;
        next = phases[i].last + 1;
        EXPECT_FALSE(phases[i].empty()) << phases[i].name;
    }
    EXPECT_EQ(next, 601u);
    EXPECT_GT(phases[0].moving_share, 0.9);  // everything falls
    EXPECT_LT(phases[3].moving_share, kAsleepShare);
    // Brownian never sleeps: its bodies are re-kicked, so no asleep phase.
    const std::vector<MotionPhase> b = motion_phases(generate_scene(broadmark("brownian", "cubes", 200, 60)));
    EXPECT_TRUE(b[3].empty());
    EXPECT_EQ(b[0].first, 1u);
    EXPECT_EQ(b[2].last, 60u);
}

TEST(PhysicsScenes, ExperimentsMeasureAWindowOfFrames) {
    const Experiment e = parse_experiment(
        R"({"scenes": [{"generator": "pile", "objects": 120, "frames": 600, "rays_per_frame": 20,
                        "phases": ["falling", "asleep"], "stride": 2},
                       {"generator": "pile", "objects": 120, "frames": 600, "rays_per_frame": 20, "start_frame": 250,
                        "stride": 10},
                       {"generator": "brownian", "objects": 100, "frames": 20, "phases": "asleep"}],
            "structures": [{"name": "bf"}]})",
        "exp.json", ".");
    ASSERT_EQ(e.scenes.size(), 4u);
    EXPECT_EQ(e.scenes[0].name, "pile-falling");
    EXPECT_EQ(e.scenes[1].name, "pile-asleep");
    EXPECT_EQ(e.scenes[1].key["measure"], nlohmann::json({{"phase", "asleep"}, {"stride", 2}}));
    EXPECT_EQ(e.scenes[2].key["measure"], nlohmann::json({{"start_frame", 250}, {"stride", 10}}));
    // Every frame replays; only the window's are measured, the others count as warm-up.
    for (std::size_t i : {1u, 2u}) {
        SCOPED_TRACE(e.scenes[i].name);
        const Recording r = load_scene(e.scenes[i]);
        const FrameWindow w = measured_window(r, "scene");
        if (i == 1) {
            const MotionPhase asleep = motion_phases(r)[3];
            EXPECT_EQ(w.first, asleep.first);
            EXPECT_EQ(w.last, asleep.last);
        } else {
            EXPECT_EQ(w.first, 250u);
            EXPECT_EQ(w.last, 600u);
        }
        const SimulationResult res = simulate(r, find_structure("bf"), nlohmann::json::object());
        ASSERT_EQ(res.frames.size(), 600u);
        for (const FrameResult& f : res.frames)
            EXPECT_EQ(f.warmup, !(f.frame >= w.first && f.frame <= w.last && (f.frame - w.first) % w.stride == 0))
                << f.frame;
        EXPECT_EQ(res.mismatches(), 0u);
    }
    // A phase the recording never reaches stops the run, naming the phases it has.
    test::expect_input_error([&] { load_scene(e.scenes[3]); },
                             "scenes[2]: scene brownian-asleep: its recording has "
                             "no asleep phase (its phases: falling 1..");
    const auto error = [](const std::string& scene) {
        return test::input_error_of([&] {
            parse_experiment(R"({"scenes": [)" + scene + R"(], "structures": [{"name": "bf"}]})", "exp.json", ".");
        });
    };
    EXPECT_EQ(error(R"({"generator": "pile", "objects": 10, "phases": "resting"})"),
              "exp.json: scenes[0].phases: expected one of falling, impact, settling, asleep, got \"resting\"");
    EXPECT_EQ(error(R"({"generator": "pile", "objects": 10, "phases": ["asleep"], "start_frame": 3})"),
              "exp.json: scenes[0].start_frame: give \"start_frame\" or \"phases\", not both");
}

TEST(PhysicsScenes, SceneInfoShowsTheMotion) {
    const std::string bin = RCBENCH_BINARY;
    const test::TempDir dir("physics");
    const std::string file = dir.file("b.rcbscene");
    ASSERT_EQ(
        ::test::run_shell(bin + " scene gen --generator brownian --objects 100 --frames 5 --rays 10 -o " + file).code,
        0);
    const ::test::Outcome info = ::test::run_shell(bin + " scene info --json " + file);
    ASSERT_EQ(info.code, 0) << info.err;
    const auto m = nlohmann::json::parse(info.out)["motion"];
    EXPECT_GE(m["changed_share"]["p10"].get<double>(), 0.99);
    EXPECT_EQ(m["first_frames"].size(), 3u);
    EXPECT_EQ(m["last_frames"].size(), 3u);
    // Broadmark's speeds, at most 0.75 L/s (L = 10 for 100 unit cubes) over 1/30 s: a step of at
    // most 0.25 of a cube, collisions aside.
    EXPECT_GT(m["move_over_size"]["median"].get<double>(), 0.02);
    EXPECT_LT(m["move_over_size"]["median"].get<double>(), 0.35);
    ASSERT_EQ(m["phases"].size(), 4u);
    EXPECT_EQ(m["phases"][0]["name"], "falling");
    EXPECT_EQ(m["phases"][0]["first"], 1);
    EXPECT_EQ(m["phases"][3]["frames"], 0);  // brownian never sleeps
    const ::test::Outcome table = ::test::run_shell(bin + " scene info " + file);
    EXPECT_NE(table.out.find("changed per frame p10 / p50 / p90"), std::string::npos) << table.out;
    EXPECT_NE(table.out.find("moving per phase (frames, share)"), std::string::npos) << table.out;
    EXPECT_NE(table.out.find("asleep none"), std::string::npos) << table.out;
}

TEST(PhysicsScenes, EveryStructureMatchesTheGroundTruth) {
    for (const char* generator : {"pile", "explosion", "collapse", "brownian", "gravity"}) {
        SceneSettings s = physics(generator, 150, 6);
        s.shape_set = std::string(generator) == "gravity"    ? "assorted"
                      : std::string(generator) == "brownian" ? "spheres"
                                                             : "";
        s.rays.per_frame = 100;
        s.rays.mix = parse_ray_mix("center,los,shots,inside,ground");
        const Recording r = generate_scene(s);
        for (const StructureInfo& info : structure_registry()) {
            SCOPED_TRACE(std::string(generator) + " / " + info.name);
            test::expect_matches_ground_truth(r, info.name);
        }
    }
}

}  // namespace
}  // namespace rcb

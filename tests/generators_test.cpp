// Generators: deterministic by seed; the scenes have the statistics they claim.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/generate/physics.h"
#include "core/scene/generate/stream.h"
#include "core/scene/recording_io.h"
#include "core/scene/recording_stream.h"

namespace rcb {
namespace {

bool interiors_overlap(const Aabb& a, const Aabb& b) {
    return a.min.x < b.max.x && b.min.x < a.max.x && a.min.y < b.max.y && b.min.y < a.max.y && a.min.z < b.max.z &&
           b.min.z < a.max.z;
}

/// Fraction of the objects whose centres fall in the densest 1% of a 32³ grid's cells.
double densest_share(const std::vector<Object>& objects) {
    const Aabb b = bounds_of(objects);
    std::map<int, int> count;
    for (const Object& o : objects) {
        int key = 0;
        for (int a = 0; a < 3; ++a) {
            const float e = b.max[a] - b.min[a];
            key = key * 32 + (e > 0 ? std::clamp(int((o.box.center()[a] - b.min[a]) / e * 32), 0, 31) : 0);
        }
        ++count[key];
    }
    std::vector<int> per_cell;
    for (auto& [k, c] : count) per_cell.push_back(c);
    std::sort(per_cell.rbegin(), per_cell.rend());
    const std::size_t top = std::max<std::size_t>(1, 32 * 32 * 32 / 100);
    int in_top = 0;
    for (std::size_t i = 0; i < std::min(top, per_cell.size()); ++i) in_top += per_cell[i];
    return double(in_top) / double(objects.size());
}

TEST(Generators, SameSeedSameBytesOtherSeedOtherScene) {
    for (const char* preset : {"uni-m", "irreg-m", "jittered-m", "clusters-m"}) {
        SceneSettings s = preset_settings(preset);
        s.frames = 3;
        s.rays.mix = parse_ray_mix("center,dense,los,ground,shots");
        const std::string a = encode_recording(generate_scene(s));
        EXPECT_EQ(a, encode_recording(generate_scene(s))) << preset;
        s.seed = 2;
        EXPECT_NE(a, encode_recording(generate_scene(s))) << preset;
    }
}

// The generator's old names, kept for one release so that code written before the rename still
// builds (with a deprecation warning, silenced here) and still picks its generator.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
TEST(Generators, TheOldNamesStillWorkForOneRelease) {
    EXPECT_EQ(scene_kinds(), scene_generators());
    EXPECT_EQ(failure_mode_kinds(), failure_mode_generators());
    EXPECT_EQ(physics_kinds(), physics_generators());
    EXPECT_TRUE(is_physics_kind("pile"));
    EXPECT_FALSE(is_physics_kind("uniform"));
    EXPECT_TRUE(is_broadmark_kind("gravity"));
    EXPECT_FALSE(is_broadmark_kind("pile"));

    // SceneSettings::kind, set as old code sets it, names the generator in place of `generator`
    // for every function that takes the settings.
    SceneSettings old = preset_settings("uni-s");
    old.frames = 3;
    old.kind = "clusters";
    SceneSettings now = old;
    now.kind.clear();
    now.generator = "clusters";
    const Recording want = generate_scene(now);
    EXPECT_EQ(nlohmann::json::parse(want.meta)["kind"], "clusters");
    EXPECT_EQ(generate_scene(old), want);
    RecordingCollector streamed;
    stream_scene(old, streamed);
    EXPECT_EQ(streamed.recording, want);
    EXPECT_EQ(generate_objects(old), want.initial);
    EXPECT_EQ(to_json(old), to_json(now));
    EXPECT_EQ(with_generator(old).generator, "clusters");
    EXPECT_TRUE(with_generator(old).kind.empty());

    SceneSettings bodies;
    bodies.kind = "brownian";
    bodies.objects = 40;
    bodies.frames = 2;
    bodies.rays.per_frame = 5;
    EXPECT_DOUBLE_EQ(physics_time_step(bodies), 1.0 / 30);  // Broadmark's, not rcbench's 1/60
    SceneSettings bodies_now = bodies;
    bodies_now.kind.clear();
    bodies_now.generator = "brownian";
    EXPECT_EQ(generate_physics_scene(bodies), generate_scene(bodies_now));
}
#pragma GCC diagnostic pop

TEST(Generators, RayCountDoesNotChangeTheDynamics) {
    SceneSettings s = preset_settings("irreg-s");
    s.frames = 4;
    const Recording a = generate_scene(s);
    s.rays.per_frame = 10;
    const Recording b = generate_scene(s);
    for (std::size_t f = 0; f < a.frames.size(); ++f) {
        EXPECT_EQ(a.frames[f].moves, b.frames[f].moves);
        EXPECT_EQ(a.frames[f].inserts, b.frames[f].inserts);
    }
}

TEST(Generators, PresetsHaveTheThesisCounts) {
    EXPECT_EQ(preset_settings("uni-s").objects, 99u);
    EXPECT_EQ(preset_settings("uni-m").objects, 5104u);
    EXPECT_EQ(preset_settings("irreg-l").objects, 14021u);
    EXPECT_EQ(preset_settings("irreg-xl").objects, 1000000u);
    EXPECT_EQ(generate_objects(preset_settings("irreg-l")).size(), 14021u);
    EXPECT_EQ(generate_objects(preset_settings("uni-s")).size(), 99u);
    EXPECT_EQ(preset_settings("jittered-l").objects, 14021u);
    EXPECT_EQ(preset_settings("clusters-m").objects, 5104u);
    EXPECT_EQ(preset_settings("clusters-xl").objects, 1000000u);
    EXPECT_EQ(generate_objects(preset_settings("clusters-l")).size(), 14021u);
    EXPECT_THROW(preset_settings("uni-xl"), InputError);
    EXPECT_THROW(preset_settings("jittered-xl"), InputError);
    EXPECT_THROW(preset_settings("clusters-s"), InputError);
    EXPECT_THROW(preset_settings("huge"), InputError);
}

TEST(Generators, UniformObjectsAreSimilarSizedAndDoNotOverlap) {
    std::vector<Object> objects = generate_objects(preset_settings("uni-l"));
    std::sort(objects.begin(), objects.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    float smallest = INFINITY, largest = 0;
    for (std::size_t i = 0; i < objects.size(); ++i) {
        smallest = std::min(smallest, objects[i].box.longest_edge());
        largest = std::max(largest, objects[i].box.longest_edge());
        for (std::size_t j = i + 1; j < objects.size() && objects[j].box.min.x < objects[i].box.max.x; ++j)
            ASSERT_FALSE(interiors_overlap(objects[i].box, objects[j].box)) << objects[i].uid << " " << objects[j].uid;
    }
    EXPECT_LT(largest / smallest, 2.0f);
    EXPECT_LT(densest_share(objects), 0.05);
}

TEST(Generators, JitteredBoxesFillTheirOwnCellsWithoutOverlap) {
    std::vector<Object> objects = generate_objects(preset_settings("jittered-l"));
    std::sort(objects.begin(), objects.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    for (std::size_t i = 0; i < objects.size(); ++i) {
        const Aabb& b = objects[i].box;
        for (int a = 0; a < 3; ++a) {
            EXPECT_GE(b.max[a] - b.min[a], 3.999f);  // 4 to 8 units per axis, in a 10-unit cell
            EXPECT_LE(b.max[a] - b.min[a], 8.001f);
            EXPECT_EQ(std::floor(b.min[a] / 10), std::floor(std::nextafter(b.max[a], 0.0f) / 10));  // one cell
        }
        for (std::size_t j = i + 1; j < objects.size() && objects[j].box.min.x < objects[i].box.max.x; ++j)
            ASSERT_FALSE(interiors_overlap(objects[i].box, objects[j].box)) << objects[i].uid << " " << objects[j].uid;
    }
}

/// The longest edges' 10th, 50th and 90th percentiles.
std::array<float, 3> edge_percentiles(const std::vector<Object>& objects) {
    std::vector<float> e;
    for (const Object& o : objects) e.push_back(o.box.longest_edge());
    std::sort(e.begin(), e.end());
    return {e[e.size() / 10], e[e.size() / 2], e[e.size() * 9 / 10]};
}

TEST(Generators, ClustersMatchThePeerSceneDescription) {
    // The peer-comparison irregular scene: longest edges 1.05 / 2.85 / 8.9 at the 10th / 50th / 90th
    // percentile, 21 huge objects, 5% of the objects inside them; the sizes stay absolute at 10^5.
    for (std::uint32_t n : {14021u, 100000u}) {
        SceneSettings s = preset_settings("clusters-l");
        s.objects = n;
        const std::vector<Object> objects = generate_objects(s);
        const std::array<float, 3> p = edge_percentiles(objects);
        EXPECT_NEAR(p[0], 1.05, 0.2 * 1.05) << n;
        EXPECT_NEAR(p[1], 2.85, 0.2 * 2.85) << n;
        EXPECT_NEAR(p[2], 8.9, 0.2 * 8.9) << n;
        std::vector<Aabb> huge;
        for (const Object& o : objects)
            if (o.box.longest_edge() >= 30 && o.uid <= std::lround(n * 0.0015)) huge.push_back(o.box);
        EXPECT_EQ(huge.size(), std::size_t(std::lround(n * 0.0015))) << n;
        std::size_t inside = 0;
        for (const Object& o : objects)
            for (const Aabb& h : huge)
                if (o.box.longest_edge() < 30 && h.contains(Aabb{o.box.center(), o.box.center()})) {
                    ++inside;
                    break;
                }
        EXPECT_GE(inside, objects.size() / 20) << n;  // 5% placed inside, plus cluster objects that fall in
    }
}

TEST(Generators, IrregularScenesAreSkewedClusteredAndNested) {
    const std::vector<Object> objects = generate_objects(preset_settings("irreg-l"));
    std::vector<float> edges;
    for (const Object& o : objects) edges.push_back(o.box.longest_edge());
    std::sort(edges.begin(), edges.end());
    EXPECT_GE(edges.back() / edges.front(), 1000.0f);        // three orders of magnitude
    EXPECT_LT(edges[edges.size() / 2], edges.back() / 100);  // most objects small
    EXPECT_GT(densest_share(objects), 0.3);                  // crowded into clusters
    // A few very large objects cover big parts of the scene, and small ones sit inside them.
    const Aabb bounds = bounds_of(objects);
    std::vector<Aabb> large;
    for (const Object& o : objects)
        if (o.box.longest_edge() > 0.05f * bounds.longest_edge()) large.push_back(o.box);
    EXPECT_GE(large.size(), 10u);
    EXPECT_LT(large.size(), objects.size() / 100);
    std::size_t nested = 0;
    for (const Object& o : objects)
        if (o.box.longest_edge() < 5)
            for (const Aabb& l : large)
                if (l.contains(o.box)) {
                    ++nested;
                    break;
                }
    EXPECT_GT(nested, objects.size() / 10);
}

TEST(Generators, DynamicsChangeTheRequestedShareWithSmallMoves) {
    SceneSettings s = preset_settings("irreg-m");
    s.frames = 5;
    const Recording r = generate_scene(s);
    LiveSet live(r.initial);
    for (const Frame& f : r.frames) {
        EXPECT_EQ(f.change_count(), std::size_t(std::llround(0.01 * live.size())));
        EXPECT_GT(f.moves.size(), f.inserts.size() + f.removes.size());  // moves dominate
        for (const Object& m : f.moves) {
            const Aabb& before = live.box(m.uid);
            const float reach = 0.1f * before.longest_edge() * 1.001f;
            for (int a = 0; a < 3; ++a) EXPECT_LE(std::abs(m.box.min[a] - before.min[a]), reach + 1e-3f);
        }
        live.apply(f);
    }
}

TEST(Generators, RayModesDoWhatTheySay) {
    const std::vector<Object> objects = generate_objects(preset_settings("irreg-s"));
    const Aabb b = bounds_of(objects);
    const Vec3 c = b.center();
    const float half_diagonal =
        0.5f * std::sqrt(b.extent().x * b.extent().x + b.extent().y * b.extent().y + b.extent().z * b.extent().z);
    RaySettings center;
    center.per_frame = 200;
    for (const Segment& s : generate_rays(objects, center, 1, 1)) {
        EXPECT_EQ(s.p0, c);
        const Vec3 d = s.delta();
        EXPECT_GE(std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z), half_diagonal);  // leaves the scene
    }
    RaySettings ground;
    ground.per_frame = 100;
    ground.mix = parse_ray_mix("ground");
    for (const Segment& s : generate_rays(objects, ground, 1, 1)) {
        EXPECT_EQ(s.p0.x, s.p1.x);
        EXPECT_EQ(s.p0.z, s.p1.z);
        EXPECT_LT(s.p1.y, s.p0.y);  // downward
    }
    RaySettings mix;
    mix.per_frame = 10;
    mix.mix = parse_ray_mix("center:0.7,los:0.3");
    EXPECT_EQ(generate_rays(objects, mix, 1, 1).size(), 10u);
    EXPECT_THROW(parse_ray_mix("center,sideways"), InputError);
    EXPECT_THROW(parse_ray_mix("center:-1"), InputError);
    EXPECT_THROW(parse_ray_mix("center:0"), InputError);
}

}  // namespace
}  // namespace rcb

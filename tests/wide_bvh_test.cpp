// The wide BVH (wbvh): differential tests against the ground truth on the hard scenes, generated
// scenes and the presets over several parameter sets; churn with validate() after every change
// batch, answers against brute force (the same float slab test) and the SAH cost held by the
// rebuild policy; nested inserts into an empty tree; closest and any hit.
#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include "core/error.h"
#include "core/generators.h"
#include "core/random.h"
#include "core/registry.h"
#include "core/structures/brute_force.h"
#include "core/structures/wide_bvh.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

std::vector<nlohmann::json> wbvh_param_sets(std::uint64_t seed) {
    std::vector<nlohmann::json> sets{nlohmann::json::object(), {{"rebuild_ratio", 0.0}},
                                     {{"rebuild_ratio", 1.0}}, {{"width", 2}, {"leaf_size", 1}, {"bins", 2}},
                                     {{"leaf_size", 8}},       {{"reinsert", true}, {"rebuild_ratio", 0.0}}};
    Random rng(seed);
    for (int i = 0; i < 2; ++i)
        sets.push_back({{"width", int(2 + rng.below(7))},
                        {"leaf_size", int(1 + rng.below(8))},
                        {"bins", int(2 + rng.below(31))},
                        {"rebuild_ratio", rng.below(3) == 0 ? 0.0 : rng.uniform(1.0, 2.0)},
                        {"reinsert", rng.below(2) == 1}});
    return sets;
}

TEST(WideBvh, MatchesGroundTruthOnEveryHardSceneWithRandomParams) {
    std::uint64_t seed = 1;
    for (const test::NamedScene& s : test::hard_scenes())
        for (const nlohmann::json& p : wbvh_param_sets(seed++))
            test::expect_matches_ground_truth(s.recording, "wbvh", p, s.name);
}

TEST(WideBvh, MatchesGroundTruthOnGeneratedScenes) {
    for (const char* kind : {"uniform", "irregular"})
        for (const nlohmann::json& p : wbvh_param_sets(99)) {
            const Recording r = test::generated_scene(kind, 600, 12, 7, 0.2);
            test::expect_matches_ground_truth(r, "wbvh", p, kind);
        }
}

TEST(WideBvh, MatchesGroundTruthOnThePresets) {
    for (const char* name : {"uni-s", "uni-m", "irreg-s", "irreg-m", "irreg-l"}) {
        SceneSettings s = preset_settings(name);
        s.frames = 3;
        s.dynamics.change_fraction = 0.05;
        s.rays.per_frame = 200;
        s.rays.mix = parse_ray_mix("center:2,dense:1,los:1,ground:1,shots:1,faces:1");
        const Recording r = generate_scene(s);
        for (const nlohmann::json& p : {nlohmann::json::object(), nlohmann::json{{"rebuild_ratio", 0.0}}}) {
            const SimulationResult res = test::expect_matches_ground_truth(r, "wbvh", p, name);
            for (const FrameResult& f : res.frames) {
                EXPECT_EQ(f.counters.n_tp, f.hits) << name;
                EXPECT_GE(f.counters.n_rb, f.counters.n_tp) << name;
                EXPECT_GE(f.counters.n_t, f.rays) << name;
                for (const char* key : {"sah_cost", "depth", "nodes", "leaves", "rebuilds"})
                    EXPECT_TRUE(f.stats.contains(key)) << key;
            }
        }
    }
}

/// Churn: removes, inserts (leaves fill and split) and moves of up to an object size, then far
/// jumps. validate() after every batch of changes (a commit each), answers checked against brute
/// force, and the SAH cost: its growth since the last build never above rebuild_ratio at a commit,
/// and within that bound (plus the slack of a different build order) of a fresh build.
TEST(WideBvh, ChurnKeepsTheTreeValidAndItsSahCostWithinThePolicy) {
    constexpr int kObjects = 400, kFrames = 1500;
    constexpr float kWorld = 60;
    for (const double ratio : {1.3, 2.0, 0.0}) {
        Random rng(2024);
        WideBvh tree(WideBvh::Params{.rebuild_ratio = ratio});
        BruteForce bf;
        std::vector<Object> live;
        Uid next = 0;
        for (int i = 0; i < kObjects; ++i) live.push_back({next++, test::random_box(rng, kWorld)});
        tree.build(live);
        bf.build(live);
        double worst_vs_fresh = 0;
        for (int frame = 0; frame < kFrames; ++frame) {
            const bool jumps = frame >= kFrames / 2;  // the second half moves objects anywhere
            for (int batch = 0; batch < 3; ++batch) {
                for (int c = 0; c < 5; ++c) test::random_change(rng, live, next, kWorld, jumps, {&tree, &bf});
                tree.commit();
                bf.commit();
                ASSERT_NO_THROW(tree.validate()) << "frame " << frame << " batch " << batch;
                if (ratio > 0) {
                    const nlohmann::json st = tree.stats();
                    ASSERT_LE(st["sah_growth"].get<double>(), ratio * (1 + 1e-9)) << "frame " << frame;
                }
            }
            for (int k = 0; k < 3; ++k) {
                const Segment ray = test::random_segment(rng, kWorld);
                ASSERT_EQ(test::sorted_hits(tree, ray), test::sorted_hits(bf, ray))
                    << "frame " << frame << " ray " << k;
            }
            if (frame % 100 == 99) {
                WideBvh fresh;
                fresh.build(live);
                worst_vs_fresh = std::max(worst_vs_fresh, tree.sah_cost() / fresh.sah_cost());
            }
        }
        const nlohmann::json st = tree.stats();
        std::cout << "[ churn    ] rebuild_ratio=" << ratio << ": worst SAH cost vs a fresh build " << worst_vs_fresh
                  << "x; " << st.dump() << '\n';
        if (ratio > 0) {
            EXPECT_LT(worst_vs_fresh, ratio * 1.25);
            EXPECT_GT(st["rebuilds"].get<int>(), 0);
        } else {
            EXPECT_EQ(st["rebuilds"].get<int>(), 0);
        }
        EXPECT_GT(st["leaf_splits"].get<int>(), 0);
    }
}

/// Boxes nested around one centre, inserted one by one into an empty tree: full leaves split and
/// push down; the tree stays valid and rays from the centre meet every box.
TEST(WideBvh, NestedInsertsIntoAnEmptyTree) {
    WideBvh tree(WideBvh::Params{.rebuild_ratio = 0.0});
    tree.build({});
    std::vector<Object> live;
    for (Uid u = 0; u < 300; ++u) {
        const float h = 1.0f + float(u);
        live.push_back({u, {{-h, -h, -h}, {h, h, h}}});
        tree.insert(live.back());
        tree.commit();
        ASSERT_NO_THROW(tree.validate()) << u;
    }
    const Segment ray{{0, 0, 0}, {1, 0, 0}};
    EXPECT_EQ(test::sorted_hits(tree, ray).size(), live.size());
    for (Uid u = 0; u < 300; u += 2) {
        tree.remove(u);
        tree.commit();
        ASSERT_NO_THROW(tree.validate()) << u;
    }
    EXPECT_EQ(test::sorted_hits(tree, ray).size(), 150u);
    for (Uid u = 1; u < 300; u += 2) tree.remove(u);
    tree.commit();
    tree.validate();
    EXPECT_EQ(tree.size(), 0u);
    EXPECT_TRUE(test::sorted_hits(tree, ray).empty());
}

TEST(WideBvh, ClosestAndAnyHitStopEarly) {
    WideBvh tree;
    std::vector<Object> objects;
    for (Uid u = 0; u < 100; ++u) objects.push_back({u, {{float(u) * 2, 0, 0}, {float(u) * 2 + 1, 1, 1}}});
    tree.build(objects);
    const Segment ray{{-1, 0.5f, 0.5f}, {300, 0.5f, 0.5f}};
    const std::optional<Hit> h = tree.cast_closest(ray);
    ASSERT_TRUE(h.has_value());
    EXPECT_EQ(h->uid, 0u);
    EXPECT_FLOAT_EQ(h->t, 1.0f / 301.0f);
    EXPECT_TRUE(tree.cast_any(ray));
    EXPECT_FALSE(tree.cast_any({{-1, 5, 5}, {300, 5, 5}}));
    Counters c;
    HitLists out;
    tree.cast_counted(std::span<const Segment>(&ray, 1), out, c);
    EXPECT_EQ(c.n_tp, 100u);
    EXPECT_EQ(out.uids.size(), 100u);
}

TEST(WideBvh, RejectsInvalidParams) {
    const StructureInfo& w = find_structure("wbvh");
    EXPECT_THROW(w.make({{"width", 1}}, "params"), InputError);
    EXPECT_THROW(w.make({{"width", 9}}, "params"), InputError);
    EXPECT_THROW(w.make({{"leaf_size", 0}}, "params"), InputError);
    EXPECT_THROW(w.make({{"leaf_size", 9}}, "params"), InputError);
    EXPECT_THROW(w.make({{"bins", 1}}, "params"), InputError);
    EXPECT_THROW(w.make({{"rebuild_ratio", -1}}, "params"), InputError);
    EXPECT_THROW(w.make({{"ratio", 1.2}}, "params"), InputError);
    EXPECT_NO_THROW(w.make({{"width", 4}, {"leaf_size", 2}, {"rebuild_ratio", 1.5}}, "params"));
}

}  // namespace
}  // namespace rcb

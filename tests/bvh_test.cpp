// The dynamic BVH (dbvh) and the linear BVH (lbvh): differential tests against the ground truth
// over random parameters, a long churn run (correctness and SAH-cost drift of the incremental
// tree), identical LBVH trees for every thread count, and parameter validation.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <tuple>
#include <iostream>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "accel/scan/brute_force.h"
#include "accel/bvh/dynamic_bvh.h"
#include "accel/bvh/linear_bvh.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

/// The defaults, both modes and the two cases random draws rarely meet: a rebuild on growth alone
/// and thin boxes without rotations. Random sets on the hard scenes: conformance_test.cpp.
const std::vector<nlohmann::json> kDbvhParamSets{nlohmann::json::object(),
                                                 {{"mode", "rebuild"}},
                                                 {{"mode", "rebuild"}, {"rebuild_every", 0}, {"rebuild_growth", 1.01}},
                                                 {{"margin", 0.0}, {"rotate", false}}};

/// kDbvhParamSets and three sets drawn from the dbvh's parameter specs.
std::vector<nlohmann::json> dbvh_param_sets(std::uint64_t seed) {
    std::vector<nlohmann::json> sets = kDbvhParamSets;
    Random rng(seed);
    for (int i = 0; i < 3; ++i) sets.push_back(test::random_params(find_structure("dbvh"), rng));
    return sets;
}

TEST(DynamicBvh, MatchesGroundTruthOnEveryHardSceneWithChosenParams) {
    for (const test::NamedScene& s : test::hard_scenes())
        for (const nlohmann::json& p : kDbvhParamSets)
            test::expect_matches_ground_truth(s.recording, "dbvh", p, s.name);
}

TEST(LinearBvh, MatchesGroundTruthOnEveryHardScene) {
    for (const test::NamedScene& s : test::hard_scenes())
        for (int threads : {1, 2})
            test::expect_matches_ground_truth(s.recording, "lbvh", {{"threads", threads}}, s.name);
}

TEST(DynamicBvh, MatchesGroundTruthOnGeneratedScenes) {
    for (const char* generator : {"uniform", "irregular"})
        for (const nlohmann::json& p : dbvh_param_sets(99)) {
            const Recording r = test::generated_scene(generator, 400, 12, 7, 0.1);
            test::expect_matches_ground_truth(r, "dbvh", p, generator);
        }
}

TEST(LinearBvh, MatchesGroundTruthOnGeneratedScenes) {
    for (const char* generator : {"uniform", "irregular"})
        for (int threads : {1, 2}) {
            const Recording r = test::generated_scene(generator, 400, 12, 8, 0.1);
            test::expect_matches_ground_truth(r, "lbvh", {{"threads", threads}}, generator);
        }
}

/// The thesis presets (uni-s … irreg-l; irreg-xl is a benchmark, not a test), a few frames each
/// with every ray mode and more changes than the presets' 1 %.
TEST(Bvh, MatchesGroundTruthOnThePresets) {
    for (const char* name : {"uni-s", "uni-m", "uni-l", "irreg-s", "irreg-m", "irreg-l"}) {
        SceneSettings s = preset_settings(name);
        s.frames = 3;
        s.dynamics.change_fraction = 0.05;
        s.rays.per_frame = 200;
        s.rays.mix = parse_ray_mix("center:2,dense:1,los:1,ground:1,shots:1");
        const Recording r = generate_scene(s);
        for (const auto& [structure, params] : std::vector<std::pair<std::string, nlohmann::json>>{
                 {"dbvh", nlohmann::json::object()},
                 {"dbvh", {{"mode", "rebuild"}, {"margin", 0.0}}},
                 {"dbvh", {{"mode", "rebuild"}, {"rebuild_every", 2}, {"rotate", false}}},
                 {"lbvh", {{"threads", 1}}},
                 {"lbvh", {{"threads", 2}}}}) {
            const SimulationResult res = test::expect_matches_ground_truth(r, structure, params, name);
            // The counters: every reported hit is one N_TP, every object test one N_RB, and a
            // non-empty tree is entered once per ray at least.
            for (const FrameResult& f : res.frames) {
                EXPECT_EQ(f.counters.n_tp, f.hits) << structure << ' ' << name;
                EXPECT_GE(f.counters.n_rb, f.counters.n_tp) << structure << ' ' << name;
                EXPECT_GE(f.counters.n_t, f.rays) << structure << ' ' << name;
                EXPECT_TRUE(f.stats.contains("sah_cost") && f.stats.contains("depth"));
            }
        }
    }
}

/// 0, 1 and 2 objects, with inserts, moves and removes through those sizes.
TEST(Bvh, ZeroOneAndTwoObjects) {
    const Aabb a{{0, 0, 0}, {1, 1, 1}}, b{{3, 0, 0}, {4, 1, 1}};
    const std::vector<Segment> rays{
        {{-1, 0.5f, 0.5f}, {5, 0.5f, 0.5f}}, {{0.5f, 0.5f, 0.5f}, {0.5f, 0.5f, 0.5f}}, {{1, 1, 1}, {3, 1, 1}},
        {{-1, -1, -1}, {-2, -2, -2}},        {{3.5f, 2, 0.5f}, {3.5f, -2, 0.5f}},      {{4, 1, 1}, {10, 1, 1}}};
    for (std::size_t initial = 0; initial <= 2; ++initial) {
        Recording r;
        std::vector<Object> all{{10, a}, {20, b}};
        r.initial.assign(all.begin(), all.begin() + std::ptrdiff_t(initial));
        Frame f1;  // move what there is
        for (const Object& o : r.initial)
            f1.moves.push_back({o.uid, {o.box.min + Vec3{0.25f, 0, 0}, o.box.max + Vec3{0.25f, 0, 0}}});
        f1.rays = rays;
        Frame f2;  // remove everything
        for (const Object& o : r.initial) f2.removes.push_back(o.uid);
        f2.rays = rays;
        Frame f3;  // insert two
        f3.inserts = {{30, a}, {40, b}};
        f3.rays = rays;
        Frame f4;  // remove one
        f4.removes = {30};
        f4.rays = rays;
        r.frames = {f1, f2, f3, f4};
        for (const nlohmann::json& p : dbvh_param_sets(initial))
            test::expect_matches_ground_truth(r, "dbvh", p, "tiny");
        for (int threads : {1, 2}) test::expect_matches_ground_truth(r, "lbvh", {{"threads", threads}}, "tiny");
    }
}

/// 10 000 frames of churn (removes, inserts, moves of up to an object size): every frame checked
/// against brute force (same float slab test, so the answers must be identical), check() every
/// frame, and the SAH cost drift measured against a fresh binned-SAH build of the same objects.
TEST(DynamicBvh, ChurnOf10000FramesStaysCorrectAndItsSahCostBounded) {
    constexpr int kObjects = 300, kFrames = 10000;
    constexpr float kWorld = 60;
    for (bool rotate : {true, false}) {
        Random rng(2024);
        DynamicBvh tree(DynamicBvh::Params{.margin = 0.1, .rotate = rotate});
        BruteForce bf;
        std::vector<Object> live;
        Uid next = 0;
        for (int i = 0; i < kObjects; ++i) live.push_back({next++, test::random_box(rng, kWorld)});
        tree.build(live);
        bf.build(live);
        const double cost0 = tree.sah_cost();
        double worst_ratio = 0, last_ratio = 0;
        for (int frame = 0; frame < kFrames; ++frame) {
            for (int c = 0; c < 15; ++c) test::random_change(rng, live, next, kWorld, false, {&tree, &bf});
            tree.commit();
            bf.commit();
            ASSERT_NO_THROW(tree.check()) << "frame " << frame;
            for (int k = 0; k < 3; ++k) {
                const Segment ray = test::random_segment(rng, kWorld);
                ASSERT_EQ(test::sorted_hits(tree, ray), test::sorted_hits(bf, ray))
                    << "frame " << frame << " ray " << k;
            }
            if (frame % 500 == 499 || frame == kFrames - 1) {
                DynamicBvh fresh(DynamicBvh::Params{.margin = 0.1, .mode = "rebuild"});
                fresh.build(live);
                last_ratio = tree.sah_cost() / fresh.sah_cost();
                worst_ratio = std::max(worst_ratio, last_ratio);
            }
        }
        std::cout << "[ churn    ] rotate=" << rotate << ": SAH cost " << cost0 << " after build, " << tree.sah_cost()
                  << " after " << kFrames << " frames; vs a fresh binned-SAH build: worst " << worst_ratio << "x, last "
                  << last_ratio << "x; depth " << tree.height() << '\n';
        RecordProperty(rotate ? "sah_ratio_rotate" : "sah_ratio_no_rotate", std::to_string(worst_ratio));
        EXPECT_LT(worst_ratio, 3.0);  // bounded: the incremental tree stays within 3× of a full SAH build
        EXPECT_LT(tree.height(), 40);
    }
}

/// Karras' construction is deterministic: 1 and 2 threads give the same node arrays, also with
/// duplicate Morton codes (many objects on a coarse lattice) and after changes.
TEST(LinearBvh, OneAndTwoThreadsBuildIdenticalTrees) {
    Random rng(5);
    std::vector<Object> objects;
    for (Uid u = 0; u < 200000; ++u) {
        Aabb b = test::random_box(rng, 1000);
        if (u % 3 == 0) {  // lattice: duplicate centroids and codes
            const Vec3 c{float(rng.below(8)), float(rng.below(8)), float(rng.below(8))};
            b = {c, c + Vec3{1, 1, 1}};
        }
        objects.push_back({u, b});
    }
    LinearBvh one(LinearBvh::Params{.threads = 1}), two(LinearBvh::Params{.threads = 2});
    one.build(objects);
    two.build(objects);
    one.check();
    two.check();
    ASSERT_EQ(one.nodes().size(), two.nodes().size());
    EXPECT_TRUE(one.nodes() == two.nodes());
    EXPECT_TRUE(one.meta() == two.meta());
    // The runs of equal codes (ordered by size, chunk by chunk on two threads) counted alike.
    EXPECT_GT(one.stats()["tied_codes"].get<std::size_t>(), 10000u);
    EXPECT_EQ(one.stats(), two.stats());
    for (Uid u = 0; u < 20000; ++u) {
        one.remove(u * 7), two.remove(u * 7);
        const Object moved{u * 7 + 1, test::random_box(rng, 1000)};
        one.move(moved), two.move(moved);
    }
    one.commit();
    two.commit();
    one.check();
    two.check();
    EXPECT_TRUE(one.nodes() == two.nodes());
    EXPECT_TRUE(one.meta() == two.meta());
}

/// The most build threads the parameter allows fill every per-chunk array (kMaxChunks chunks):
/// the same tree as one thread, on the radix path and then from the last rebuild's order (two far
/// objects hold the code bounds while 1 000 others move).
TEST(LinearBvh, MostThreadsBuildTheOneThreadTree) {
    Random rng(23);
    std::vector<Object> objects{{0, {Vec3{-2000, -2000, -2000}, Vec3{-1999, -1999, -1999}}},
                                {1, {Vec3{3000, 3000, 3000}, Vec3{3001, 3001, 3001}}}};
    for (Uid u = 2; u < 30000; ++u) objects.push_back({u, test::random_box(rng, 1000)});
    LinearBvh one(LinearBvh::Params{.threads = 1}), most(LinearBvh::Params{.threads = LinearBvh::kMaxThreads});
    one.build(objects);
    most.build(objects);
    most.check();
    EXPECT_FALSE(most.last_resorted());
    EXPECT_TRUE(one.nodes() == most.nodes());
    EXPECT_TRUE(one.meta() == most.meta());
    for (Uid u = 0; u < 1000; ++u) {
        const Object moved{2 + u * 13, test::random_box(rng, 1000)};
        one.move(moved), most.move(moved);
    }
    one.commit();
    most.commit();
    most.check();
    EXPECT_TRUE(most.last_resorted());
    EXPECT_TRUE(one.nodes() == most.nodes());
    EXPECT_TRUE(one.meta() == most.meta());
    EXPECT_EQ(one.stats(), most.stats());
}

/// The sort from the last rebuild's order (coherent_sort) gives the radix sort's tree exactly:
/// 20 rebuilds of 30 000 objects with moves small and large, removes and inserts, and runs of equal
/// codes, for 1 and 2 threads. It is taken whenever at most 1/16 of the objects changed and the
/// code bounds stayed (two far objects hold them), and not otherwise: in frame 10 a sixth of the
/// objects change, in frames 5 and 15 a third object moves beyond the bounds.
TEST(LinearBvh, CoherentSortBuildsTheRadixSortsTree) {
    for (int threads : {1, 2}) {
        Random rng(17);
        std::vector<Object> live{{0, {Vec3{-2000, -2000, -2000}, Vec3{-1999, -1999, -1999}}},
                                 {1, {Vec3{3000, 3000, 3000}, Vec3{3001, 3001, 3001}}},
                                 {2, {Vec3{500, 500, 500}, Vec3{501, 501, 501}}}};
        constexpr std::size_t kFixed = 3;  // never changed at random
        Uid next = kFixed;
        auto random_object = [&](Uid uid) {
            Aabb b = test::random_box(rng, 1000);
            if (uid % 5 == 0) {  // a lattice: equal codes
                const Vec3 c{float(rng.below(6)) * 100, float(rng.below(6)) * 100, float(rng.below(6)) * 100};
                const float h = float(1 + rng.below(4));
                b = {c - Vec3{h, h, h}, c + Vec3{h, h, h}};
            }
            return Object{uid, b};
        };
        while (live.size() < 30000) live.push_back(random_object(next++));
        LinearBvh coherent(LinearBvh::Params{.threads = threads}),
            radix(LinearBvh::Params{.threads = threads, .coherent_sort = false});
        coherent.build(live);
        radix.build(live);
        for (int frame = 0; frame < 20; ++frame) {
            const int changes = frame == 10 ? 5000 : 1500;
            for (int c = 0; c < changes; ++c) {
                const std::size_t i = kFixed + rng.below(live.size() - kFixed);
                const std::uint64_t kind = rng.below(10);
                if (kind == 0) {  // remove
                    coherent.remove(live[i].uid), radix.remove(live[i].uid);
                    live[i] = live.back();
                    live.pop_back();
                } else if (kind == 1) {  // insert
                    live.push_back(random_object(next++));
                    coherent.insert(live.back()), radix.insert(live.back());
                } else {  // move: mostly a little, sometimes far (inside the bounds)
                    Object& o = live[i];
                    const float d = kind == 2 ? 500.0f : 2.0f;
                    const Vec3 shift{float(rng.uniform(-0.5, 0.5)) * d, float(rng.uniform(-0.5, 0.5)) * d,
                                     float(rng.uniform(-0.5, 0.5)) * d};
                    o.box = {o.box.min + shift, o.box.max + shift};
                    coherent.move(o), radix.move(o);
                }
            }
            const bool beyond = frame == 5 || frame == 15;
            if (beyond) {
                const Vec3 c{float(4000 + frame), 0, 0};
                live[2].box = {c, c + Vec3{1, 1, 1}};
                coherent.move(live[2]), radix.move(live[2]);
            }
            coherent.commit();
            radix.commit();
            EXPECT_EQ(coherent.last_resorted(), frame != 10 && !beyond) << frame;
            EXPECT_FALSE(radix.last_resorted());
            ASSERT_NO_THROW(coherent.check()) << frame;
            ASSERT_TRUE(coherent.codes() == radix.codes()) << frame;
            ASSERT_TRUE(coherent.nodes() == radix.nodes()) << frame;
            ASSERT_TRUE(coherent.meta() == radix.meta()) << frame;
            EXPECT_EQ(coherent.stats(), radix.stats()) << frame;
        }
    }
}

/// The tree is Karras' binary radix tree over the sorted keys (code, then size for equal codes,
/// then slot), numbered as in Karras 2012 (an inner node sits at the end of its range where its
/// parent splits; root 0, leaves after the inner nodes): checked against a plain recursive
/// construction from std::sort, with codes computed here as docs/structures.md defines them. 5 000
/// objects take the sort's short path, 30 000 its bucket path (which also writes the leaves).
TEST(LinearBvh, IsKarrasRadixTreeOfTheSortedCodes) {
    for (const Uid count : {5000u, 30000u}) {
        Random rng(11);
        std::vector<Object> objects;
        for (Uid u = 0; u < count; ++u) {
            Aabb b = test::random_box(rng, 100);
            if (u % 4 == 0) {  // duplicate centroids with different sizes: runs of equal codes
                const Vec3 c{float(rng.below(4)) * 10, float(rng.below(4)) * 10, float(rng.below(4)) * 10};
                const float h = float(1 + rng.below(3));
                b = {c - Vec3{h, h, h}, c + Vec3{h, h, h}};
            }
            objects.push_back({u * 3 + 1, b});
        }
        for (int threads : {1, 2}) {
            LinearBvh tree(LinearBvh::Params{.threads = threads, .outlier_guard = false});
            tree.build(objects);
            tree.check();
            const std::size_t n = objects.size();
            // Codes: centroids normalised to their bounds, 21 bits per axis, x in the highest bit.
            Aabb cb = Aabb::empty();
            for (const Object& o : objects) cb.min = min(cb.min, o.box.center()), cb.max = max(cb.max, o.box.center());
            constexpr float kMax = float((1u << 21) - 1);
            struct Key {
                std::uint64_t code;
                std::uint32_t area_bits, slot;
            };
            std::vector<Key> keys;
            for (std::uint32_t i = 0; i < n; ++i) {
                const Vec3 c = objects[i].box.center();
                std::uint64_t code = 0;
                for (int a = 0; a < 3; ++a) {
                    const float ext = cb.max[a] - cb.min[a];
                    const float scale = ext > 0 ? kMax / ext : 0.0f;
                    const auto q = std::uint64_t(std::clamp((c[a] - cb.min[a]) * scale, 0.0f, kMax));
                    for (int bit = 0; bit < 21; ++bit) code |= ((q >> bit) & 1) << (3 * bit + 2 - a);
                }
                keys.push_back({code, std::bit_cast<std::uint32_t>(objects[i].box.half_area()), i});
            }
            std::sort(keys.begin(), keys.end(), [](const Key& a, const Key& b) {
                return std::tie(a.code, a.area_bits, a.slot) < std::tie(b.code, b.area_bits, b.slot);
            });
            const std::vector<LinearBvh::Node>& nodes = tree.nodes();
            ASSERT_EQ(nodes.size(), 2 * n - 1);
            ASSERT_EQ(tree.codes().size(), n);
            const std::uint32_t leaf_base = std::uint32_t(n - 1);
            for (std::size_t k = 0; k < n; ++k) {
                ASSERT_EQ(tree.codes()[k], keys[k].code) << k;
                ASSERT_EQ(nodes[leaf_base + k].child[0], objects[keys[k].slot].uid) << k;
            }
            // Karras' tree: a range splits where its first and last keys' common prefix ends (equal codes
            // compare their sorted indices); the left part is node `split` (a leaf if it is one key), the
            // right part node `split + 1`.
            auto prefix = [&](std::uint32_t i, std::uint32_t j) {
                const std::uint64_t x = keys[i].code ^ keys[j].code;
                return x ? std::countl_zero(x) : 64 + std::countl_zero(i ^ j);
            };
            std::size_t inner = 0;
            // Returns the subtree's box and sets its height.
            auto check = [&](auto&& self, std::uint32_t first, std::uint32_t last, std::uint32_t index,
                             int& height) -> Aabb {
                const LinearBvh::Node& node = nodes[index];
                if (first == last) {
                    EXPECT_EQ(index, leaf_base + first);
                    EXPECT_EQ(node.child[1], kNullNode) << index;
                    height = 0;
                    return objects[keys[first].slot].box;
                }
                ++inner;
                const int common = prefix(first, last);
                std::uint32_t split = first;  // the last key sharing more than `common` with the first
                while (prefix(first, split + 1) > common) ++split;
                const std::uint32_t left = split == first ? leaf_base + split : split;
                const std::uint32_t right = split + 1 == last ? leaf_base + split + 1 : split + 1;
                EXPECT_EQ(node.child[0], left) << index;
                EXPECT_EQ(node.child[1], right) << index;
                int h0, h1;
                const Aabb box = merge(self(self, first, split, left, h0), self(self, split + 1, last, right, h1));
                EXPECT_TRUE(node.box == box) << index;
                height = 1 + std::max(h0, h1);
                EXPECT_EQ(tree.meta()[index].height, height) << index;
                return box;
            };
            int height;
            check(check, 0, std::uint32_t(n - 1), 0, height);
            EXPECT_EQ(inner, n - 1);
            EXPECT_EQ(tree.height(), height);
        }
    }
}

TEST(Bvh, RejectsInvalidParams) {
    const StructureInfo& d = find_structure("dbvh");
    const StructureInfo& l = find_structure("lbvh");
    EXPECT_THROW(d.make({{"margin", -0.1}}, "params"), InputError);
    EXPECT_THROW(d.make({{"mode", "sometimes"}}, "params"), InputError);
    EXPECT_THROW(d.make({{"bins", 1}}, "params"), InputError);
    EXPECT_THROW(d.make({{"rebuild_every", -1}}, "params"), InputError);
    EXPECT_THROW(d.make({{"rotate", 3}}, "params"), InputError);
    EXPECT_THROW(d.make({{"margins", 0.1}}, "params"), InputError);
    EXPECT_THROW(l.make({{"threads", 0}}, "params"), InputError);
    EXPECT_THROW(l.make({{"threads", 1.5}}, "params"), InputError);
    EXPECT_THROW(l.make({{"thread", 1}}, "params"), InputError);
    EXPECT_NO_THROW(d.make({{"mode", "rebuild"}, {"rebuild_every", 5}, {"rebuild_growth", 1.2}}, "params"));
    EXPECT_NO_THROW(l.make({{"threads", 2}}, "params"));
}

}  // namespace
}  // namespace rcb

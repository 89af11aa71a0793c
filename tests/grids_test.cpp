// Uniform grid (ug) and hierarchical hash grid (hg) against the double-precision ground truth, over
// random parameter values, the hard scenes, generated scenes and a long churn run.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>

#include "core/base/error.h"
#include "core/base/random.h"
#include "accel/model/counters.h"
#include "accel/registry.h"
#include "accel/grid/hash_grid.h"
#include "accel/grid/uniform_grid.h"
#include "core/truth/hit_lists.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

nlohmann::json random_ug_params(Random& rng) { return test::random_params(find_structure("ug"), rng); }

nlohmann::json random_hg_params(Random& rng) { return test::random_params(find_structure("hg"), rng); }

TEST(UniformGrid, MatchesGroundTruthOnEveryHardSceneAtDefaults) {
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "ug", {}, s.name);
}

/// Random parameter sets on the hard scenes: conformance_test.cpp.
TEST(UniformGrid, MatchesGroundTruthOnEveryHardSceneAtTheEndsOfTheRange) {
    // The extremes of the range and the thesis' reset mode.
    for (const test::NamedScene& s : test::hard_scenes()) {
        test::expect_matches_ground_truth(s.recording, "ug", {{"density", 0.1}}, s.name);
        test::expect_matches_ground_truth(s.recording, "ug", {{"density", 64.0}, {"thesis_reset", true}}, s.name);
    }
}

TEST(UniformGrid, MatchesGroundTruthOnGeneratedScenes) {
    Random rng(302);
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
        test::expect_matches_ground_truth(test::generated_scene("uniform", 2000, 3, seed), "ug", random_ug_params(rng),
                                          "uniform");
        test::expect_matches_ground_truth(test::generated_scene("irregular", 2000, 3, seed + 10, 0.2), "ug",
                                          random_ug_params(rng), "irregular");
    }
}

TEST(HashGrid, MatchesGroundTruthOnEveryHardSceneAtDefaults) {
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "hg", {}, s.name);
}

/// Random parameter sets on the hard scenes: conformance_test.cpp.
TEST(HashGrid, MatchesGroundTruthOnEveryHardSceneDeepAndFine) {
    // Deep and fine: every split path exercised, capacity 1 splits every shared cell.
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(
            s.recording, "hg", {{"amp", 0.01}, {"max_depth", 6}, {"max_capacity", 1}, {"subdivision", 4}}, s.name);
}

TEST(HashGrid, MatchesGroundTruthOnGeneratedScenes) {
    Random rng(304);
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
        test::expect_matches_ground_truth(test::generated_scene("uniform", 2000, 3, seed), "hg", random_hg_params(rng),
                                          "uniform");
        test::expect_matches_ground_truth(test::generated_scene("irregular", 2000, 3, seed + 10, 0.2), "hg",
                                          random_hg_params(rng), "irregular");
    }
}

/// ~1000 frames of heavy churn (30% of the objects change per frame) on a small scene, validated
/// after every frame.
TEST(Grids, LongChurnRunMatchesGroundTruth) {
    const Recording r = test::generated_scene("irregular", 150, 1000, 77, 0.3);
    test::expect_matches_ground_truth(r, "ug", {{"density", 1.0}}, "churn-1000");
    test::expect_matches_ground_truth(
        r, "hg", {{"amp", 2.0}, {"max_depth", 3}, {"max_capacity", 2}, {"subdivision", 2}}, "churn-1000");
}

TEST(Grids, OutOfRangeParametersAreRefusedWithTheRange) {
    const StructureInfo& ug = find_structure("ug");
    const StructureInfo& hg = find_structure("hg");
    const auto message = test::input_error_of;
    std::string m = message([&] { ug.make({{"density", 0.001}}, "params"); });
    EXPECT_NE(m.find("density"), std::string::npos) << m;
    EXPECT_NE(m.find("0.1..64"), std::string::npos) << m;
    m = message([&] { hg.make({{"max_depth", 9}}, "params"); });
    EXPECT_NE(m.find("max_depth"), std::string::npos) << m;
    EXPECT_NE(m.find("0..6"), std::string::npos) << m;
    m = message([&] { hg.make({{"subdivision", 8}}, "params"); });
    EXPECT_NE(m.find("subdivision"), std::string::npos) << m;
    m = message([&] { hg.make({{"amp", 100.0}}, "params"); });
    EXPECT_NE(m.find("amp"), std::string::npos) << m;
    m = message([&] { hg.make({{"no_such", 1}}, "params"); });
    EXPECT_NE(m.find("no_such"), std::string::npos) << m;
    // Built in code, bypassing the registry: the constructor refuses an unbounded lattice.
    EXPECT_THROW(HashGrid(HashGrid::Params{1.0, 12, 8, 4}), InputError);
}

TEST(Grids, CellCountStaysBoundedAtTheRangeLimits) {
    // Many objects at the smallest density: the cap bounds the cells; a huge object stays linear.
    std::vector<Object> objs;
    Random rng(5);
    for (Uid i = 0; i < 20000; ++i) {
        const Vec3 p{float(rng.uniform(0, 1e4)), float(rng.uniform(0, 1)), float(rng.uniform(0, 1))};
        objs.push_back({i, {p, p + Vec3{0.1f, 0.1f, 0.1f}}});
    }
    UniformGrid ug(UniformGrid::Params{0.1, false});
    ug.build(objs);
    EXPECT_LE(ug.stats()["cells"].get<std::size_t>(), UniformGrid::kMaxCells);
    ug.check();
    HashGrid hg(HashGrid::Params{16.0, 6, 1, 4});
    hg.build(objs);
    hg.check();
    EXPECT_LT(hg.memory_bytes() / objs.size(), 4096u);
}

TEST(Grids, ClosestAndAnyHitAgreeWithBruteForce) {
    const Recording r = test::generated_scene("irregular", 1500, 2, 21, 0.1);
    Random rng(22);
    for (const char* name : {"ug", "hg"}) {
        for (int trial = 0; trial < 4; ++trial) {
            // At the box level: a candidate is no hit of the closest-hit query.
            const nlohmann::json params = test::random_params(find_structure(name), rng, {"query"});
            auto grid = find_structure(name).make(params, "params");
            auto bf = find_structure("bf").make({}, "params");
            grid->build(r.initial);
            bf->build(r.initial);
            for (const Segment& s : r.frames[0].rays) {
                const auto a = grid->cast_closest(s), b = bf->cast_closest(s);
                ASSERT_EQ(a.has_value(), b.has_value()) << name << ' ' << params.dump();
                if (a) {
                    EXPECT_EQ(a->uid, b->uid) << name << ' ' << params.dump();
                    EXPECT_EQ(a->t, b->t);
                }
                EXPECT_EQ(grid->cast_any(s), bf->cast_any(s)) << name << ' ' << params.dump();
            }
        }
    }
}

TEST(Grids, MoveInsideTheSameCellsKeepsStructureAndCounters) {
    std::vector<Object> objs;
    for (Uid i = 0; i < 64; ++i) objs.push_back({i, {{float(i), 0, 0}, {float(i) + 0.5f, 0.5f, 0.5f}}});
    for (const char* name : {"ug", "hg"}) {
        auto g = find_structure(name).make({}, "params");
        g->build(objs);
        const auto before = g->stats();
        g->move({5, {{5.1f, 0, 0}, {5.4f, 0.4f, 0.4f}}});
        g->check();
        EXPECT_EQ(g->stats()["cells"], before["cells"]) << name;
        // Far outside the initial bounds, then back.
        g->move({5, {{-500, 300, 20}, {-499, 301, 21}}});
        g->check();
        EXPECT_TRUE(g->cast_any({{-499.5f, 300.5f, 0}, {-499.5f, 300.5f, 100}})) << name;
        g->remove(5);
        g->check();
        EXPECT_FALSE(g->cast_any({{-499.5f, 300.5f, 0}, {-499.5f, 300.5f, 100}})) << name;
        EXPECT_EQ(g->size(), 63u);
    }
}

/// A grid meets an object again in every cell of it a ray crosses: it reports it once (N_TP) and
/// counts the others as dropped box hits (N_DUP, stored but not priced: docs/model.md), with the
/// per-query stamps and with the thesis' reset alike. A tree meets each object once.
TEST(Grids, AnObjectMetInSeveralCellsIsReportedOnceAndTheRestCounted) {
    std::vector<Object> objs;
    Uid uid = 0;
    for (int x = 0; x < 10; ++x)
        for (int y = 0; y < 10; ++y)
            for (int z = 0; z < 10; ++z) {
                const Vec3 lo{10.f * float(x), 10.f * float(y), 10.f * float(z)};
                objs.push_back({uid++, {lo, {lo.x + 1, lo.y + 1, lo.z + 1}}});
            }
    const Uid rod = uid;  // 40 long on x: several cells of every grid configuration below
    objs.push_back({rod, {{2, 55.2f, 55.2f}, {42, 55.8f, 55.8f}}});
    // Along the rod, in the gap between the lattice's rows: the rod is the only box met.
    const std::vector<Segment> rays{{{0, 55.5f, 55.5f}, {50, 55.5f, 55.5f}}};
    const auto counted = [&](const char* name, const nlohmann::json& params) {
        auto s = find_structure(name).make(params, "params");
        s->build(objs);
        s->commit();
        HitLists hits;
        Counters c;
        s->cast_counted(rays, hits, c);
        EXPECT_EQ(std::vector<Uid>(hits.of(0).begin(), hits.of(0).end()), std::vector<Uid>{rod}) << name;
        EXPECT_EQ(c.n_tp, 1u) << name;
        return c.n_dup;
    };
    const std::uint64_t ug = counted("ug", {{"density", 16}});
    EXPECT_GE(ug, 1u);
    EXPECT_EQ(counted("ug", {{"density", 16}, {"thesis_reset", true}}), ug);
    EXPECT_GE(counted("hg", {{"max_depth", 0}}), 1u);
    for (const char* tree : {"bf", "dbvh", "lbvh", "wbvh"})
        EXPECT_EQ(counted(tree, nlohmann::json::object()), 0u) << tree;
}

/// The large-object guard: an object joins the list when its cell range grows past max_cells cells
/// and leaves it when it shrinks back, by move, insert and remove; the grid stays
/// valid and its answers equal brute force's throughout.
TEST(Grids, LargeObjectsMoveBetweenTheListAndTheCells) {
    std::vector<Object> objs;
    for (Uid i = 0; i < 1000; ++i) {
        const float x = float(i % 10), y = float((i / 10) % 10), z = float(i / 100);
        objs.push_back({i, {{x, y, z}, {x + 0.5f, y + 0.5f, z + 0.5f}}});
    }
    const Aabb huge{{-1, -1, -1}, {11, 11, 11}}, small{{2.1f, 2.1f, 2.1f}, {2.2f, 2.2f, 2.2f}};
    Random rng(23);
    std::vector<Segment> rays;
    for (int k = 0; k < 200; ++k) {
        auto point = [&] {
            return Vec3{float(rng.uniform(-2, 12)), float(rng.uniform(-2, 12)), float(rng.uniform(-2, 12))};
        };
        rays.push_back({point(), point()});
    }
    for (const char* name : {"ug", "hg"}) {
        auto g = find_structure(name).make({}, "params");
        auto bf = find_structure("bf").make({}, "params");
        g->build(objs);
        bf->build(objs);
        const std::uint64_t at_build = g->stats()["large_objects"].get<std::uint64_t>();
        EXPECT_EQ(at_build, 0u) << name;
        auto check = [&](std::uint64_t large, const char* step) {
            g->commit(), bf->commit();
            g->check();
            EXPECT_EQ(g->stats()["large_objects"].get<std::uint64_t>(), large) << name << ' ' << step;
            HitLists a, b;
            g->cast(rays, a), bf->cast(rays, b);
            for (std::size_t r = 0; r < rays.size(); ++r) {
                std::vector<Uid> x(a.uids.begin() + a.offsets[r], a.uids.begin() + a.offsets[r + 1]);
                std::vector<Uid> y(b.uids.begin() + b.offsets[r], b.uids.begin() + b.offsets[r + 1]);
                std::sort(x.begin(), x.end()), std::sort(y.begin(), y.end());
                ASSERT_EQ(x, y) << name << ' ' << step << " ray " << r;
            }
        };
        for (Structure* s : {g.get(), bf.get()}) s->move({5, huge});
        check(1, "grown");
        for (Structure* s : {g.get(), bf.get()})
            s->move({5, {huge.min + Vec3{0.5f, 0, 0}, huge.max + Vec3{0.5f, 0, 0}}});
        check(1, "moved while large");
        for (Structure* s : {g.get(), bf.get()}) s->insert({5000, huge}), s->insert({5001, huge});
        check(3, "large inserts");
        for (Structure* s : {g.get(), bf.get()}) s->move({5, small}), s->remove(5000);
        check(1, "shrunk and removed");
        for (Structure* s : {g.get(), bf.get()}) s->remove(5001);
        check(0, "none left");
        // Off: the same huge box is stored in its cells.
        auto off = find_structure(name).make({{"max_cells", 0}}, "params");
        off->build(objs);
        off->insert({5000, huge});
        off->check();
        EXPECT_EQ(off->stats()["large_objects"].get<std::uint64_t>(), 0u) << name;
    }
}

/// A guard switched off says in stats() when it would have fired: without it a grid is unbounded
/// on such scenes (docs/structures.md), and a slow run must show why. Identical large boxes (the
/// large-object guard lists them), identical flat boxes (the hash grid's memory guard refuses the
/// splits along their plane), one far object (the outlier guard).
TEST(Grids, GuardsSwitchedOffSayWhenTheyWouldHaveFired) {
    std::vector<Object> objs, flat;
    Random rng(31);
    for (Uid i = 0; i < 300; ++i) objs.push_back({i, test::random_box(rng, 10)});
    flat = objs;
    for (Uid i = 300; i < 600; ++i) objs.push_back({i, {{1, 1, 1}, {9, 9, 9}}});
    for (Uid i = 300; i < 600; ++i) flat.push_back({i, {{2, 2, 5.05f}, {8, 8, 5.05f}}});
    auto guards_off = [](const Structure& g) {
        const nlohmann::json st = g.stats();
        return st.contains("guards_off") ? st["guards_off"] : nlohmann::json::object();
    };
    for (const char* name : {"ug", "hg"}) {
        SCOPED_TRACE(name);
        auto on = find_structure(name).make({}, "params");
        on->build(objs);
        on->commit();
        EXPECT_GE(on->stats()["large_objects"].get<std::uint64_t>(), 300u);
        EXPECT_EQ(guards_off(*on), nlohmann::json::object());
        auto off = find_structure(name).make({{"max_cells", 0}}, "params");
        off->build(objs);
        off->commit();
        off->check();
        EXPECT_EQ(off->stats()["large_objects"].get<std::uint64_t>(), 0u);
        const std::uint64_t would_list = guards_off(*off).value("max_cells", std::uint64_t(0));
        EXPECT_GE(would_list, 300u);
        off->remove(599);  // the count follows the live objects
        off->commit();
        EXPECT_EQ(guards_off(*off).value("max_cells", std::uint64_t(0)), would_list - 1);
    }
    // The hash grid's memory guard: on, it refuses splits along the plane; off, it says how often
    // it would have.
    const nlohmann::json deep = {{"max_cells", 0}, {"max_depth", 3}, {"max_capacity", 1}};
    auto guarded = find_structure("hg").make(deep, "params");
    guarded->build(flat);
    const nlohmann::json st = guarded->stats();
    EXPECT_GT(st["refused_splits"].get<std::uint64_t>() + st["guard_collapses"].get<std::uint64_t>(), 0u);
    EXPECT_FALSE(guards_off(*guarded).contains("entries_guard"));
    nlohmann::json unguarded_params = deep;
    unguarded_params["entries_guard"] = false;
    auto unguarded = find_structure("hg").make(unguarded_params, "params");
    unguarded->build(flat);
    unguarded->check();
    EXPECT_GT(guards_off(*unguarded).value("entries_guard", std::uint64_t(0)), 0u);
    // One object 1e6 away: trimmed with the outlier guard, named without it.
    std::vector<Object> outlier = objs;
    outlier.push_back({1000, {{1e6f, 1e6f, 1e6f}, {1e6f + 1, 1e6f + 1, 1e6f + 1}}});
    for (const char* name : {"ug", "hg"}) {
        SCOPED_TRACE(name);
        auto on = find_structure(name).make({}, "params");
        on->build(outlier);
        EXPECT_TRUE(on->stats()["outlier_trimmed"].get<bool>());
        EXPECT_FALSE(guards_off(*on).contains("outlier_guard"));
        auto off = find_structure(name).make({{"outlier_guard", false}}, "params");
        off->build(outlier);
        EXPECT_FALSE(off->stats()["outlier_trimmed"].get<bool>());
        EXPECT_EQ(guards_off(*off).value("outlier_guard", false), true);
    }
}

/// The hash grid without its entries guard stays bounded: a deep grid over crowded coinciding
/// surfaces split them down to max_depth (the flat scene: 1568 entries per object at depth 5,
/// minutes at depth 6), and now stops at the ceiling. Bounded work, counted in entries: at most
/// the ceiling's budget plus each object's top cells (max_cells) per object, in every frame of the
/// hard scenes with crowded surfaces, with the answers exact.
TEST(HashGrid, WithoutTheEntriesGuardTheCeilingBoundsTheWork) {
    const nlohmann::json deep = {{"entries_guard", false}, {"max_depth", 6}, {"subdivision", 4}, {"max_capacity", 1}};
    const int max_cells = find_structure("hg").defaults()["max_cells"].get<int>();
    auto bound = [&](std::size_t objects) {
        return std::size_t(HashGrid::kEntriesCeiling + max_cells) * std::max<std::size_t>(objects, 64);
    };
    std::vector<test::NamedScene> scenes = test::hard_scenes();
    const auto flat =
        std::find_if(scenes.begin(), scenes.end(), [](const test::NamedScene& s) { return s.name == "flat"; });
    ASSERT_NE(flat, scenes.end());
    auto grid = find_structure("hg").make(deep, "params");
    grid->build(flat->recording.initial);
    grid->check();
    const nlohmann::json st = grid->stats();
    ASSERT_LE(st["entries"].get<std::size_t>(), bound(flat->recording.initial.size()));
    EXPECT_GT(st["guards_off"].value("entries_ceiling", std::uint64_t(0)), 0u);
    EXPECT_GT(st["guards_off"].value("entries_guard", std::uint64_t(0)), 0u);
    for (const test::NamedScene& s : scenes) {
        if (s.name != "flat" && s.name != "lattice-faces" && s.name != "same-centroid" && s.name != "nested-crowd")
            continue;  // the crowded surfaces that ran for minutes (the others: seconds, unbounded)
        SCOPED_TRACE(s.name);
        std::size_t objects = s.recording.initial.size();  // at most, in any frame
        for (const Frame& f : s.recording.frames) objects += f.inserts.size();
        const SimulationResult res = test::expect_matches_ground_truth(s.recording, "hg", deep, s.name);
        for (const FrameResult& f : res.frames)
            EXPECT_LE(f.stats["entries"].get<std::size_t>(), bound(objects)) << "frame " << f.frame;
    }
}

}  // namespace
}  // namespace rcb

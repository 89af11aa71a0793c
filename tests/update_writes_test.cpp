// Structure::writes(): the update's footprint, one count per cell, cell entry or tree node an
// insert, remove, move or commit writes. What a move costs each structure, that an empty commit
// writes nothing, and that the counts replay the same.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/registry.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

std::unique_ptr<Structure> make(const std::string& name, const nlohmann::json& params = nlohmann::json::object()) {
    return find_structure(name).make(params, "params");
}

std::unique_ptr<Structure> built(const std::string& name, const std::vector<Object>& objects,
                                 const nlohmann::json& params = nlohmann::json::object()) {
    auto s = make(name, params);
    s->build(objects);
    s->commit();
    return s;
}

/// `box` moved by `d` on every axis.
Aabb shifted(const Aabb& box, const Vec3& d) { return {box.min + d, box.max + d}; }

/// The growth of s.writes() over `update`.
template <class Update>
std::uint64_t writes_over(Structure& s, Update&& update) {
    const std::uint64_t before = s.writes();
    update();
    return s.writes() - before;
}

/// A 10 × 10 × 10 lattice of boxes of edge 0.2 centred at (i + 0.5, j + 0.5, k + 0.5): the world
/// box is [0.4, 9.6]³, uids 1..1000.
std::vector<Object> lattice_scene() {
    std::vector<Object> objects;
    Uid uid = 1;
    for (int i = 0; i < 10; ++i)
        for (int j = 0; j < 10; ++j)
            for (int k = 0; k < 10; ++k) {
                const Vec3 c{float(i) + 0.5f, float(j) + 0.5f, float(k) + 0.5f};
                objects.emplace_back(uid++, Aabb{c - Vec3{0.1f, 0.1f, 0.1f}, c + Vec3{0.1f, 0.1f, 0.1f}});
            }
    return objects;
}

struct Case {
    std::string name;
    nlohmann::json params;
};

/// Every own structure at its defaults, and dbvh in its rebuild mode.
std::vector<Case> own_cases() {
    std::vector<Case> cases;
    for (const char* name : {"ug", "hg", "dbvh", "lbvh", "wbvh"}) cases.push_back({name, nlohmann::json::object()});
    cases.push_back({"dbvh", {{"mode", "rebuild"}}});
    return cases;
}

TEST(UpdateWrites, AnEmptyCommitWritesNothingAndATinyMoveWrites) {
    const std::vector<Object> objects = test::generated_scene("uniform", 500, 1, 3).initial;
    const std::vector<Case> cases = own_cases();
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name + " " + c.params.dump());
        auto s = built(c.name, objects, c.params);
        // Every structure defers nothing to a commit without changes: the incremental ones have
        // nothing to refit, the rebuilding ones (lbvh, dbvh in rebuild mode) rebuild only after a
        // change.
        EXPECT_EQ(writes_over(*s, [&] { s->commit(); }), 0u);
        const Object& o = objects[objects.size() / 2];
        const float step = 1e-4f * o.box.longest_edge();
        const std::uint64_t moved = writes_over(*s, [&] {
            s->move(Object(o.uid, shifted(o.box, Vec3{step, step, step})));
            s->commit();
        });
        EXPECT_GT(moved, 0u);
        EXPECT_EQ(writes_over(*s, [&] { s->commit(); }), 0u);
        if (c.name == "dbvh" && c.params.empty()) {
            // Inside its fat box: only the leaf's own box is written, the tree stays.
            EXPECT_EQ(moved, 1u);
        } else if (c.name == "lbvh") {
            // Rebuilt whole: 2n − 1 nodes and n sorted codes (500 objects sort by radix).
            EXPECT_EQ(moved, 3 * objects.size() - 1);
        } else if (c.name != "dbvh") {
            // The incremental ones touch the object's cells or its leaf and a few blocks above it.
            EXPECT_LT(moved, 64u);
        }
        s->check();
    }
}

TEST(UpdateWrites, UniformGridMoveWritesTheCellsOfBothRanges) {
    // Density 1: 1000 objects make about 10 cells per axis over the world [0.4, 9.6]³ (no trim).
    const std::vector<Object> objects = lattice_scene();
    auto s = built("ug", objects, {{"density", 1.0}, {"outlier_guard", false}});
    const nlohmann::json stats = s->stats();
    const double size = stats["cell_size"].get<double>();
    for (int a = 0; a < 3; ++a) ASSERT_GE(stats["res"][a].get<int>(), 8);
    const double origin = 0.4;  // the world's min corner on every axis: the lattice starts there
    // A box from cell lo to cell hi per axis, a quarter cell inside each end (no plane near it).
    auto box_of = [&](std::array<int, 3> lo, std::array<int, 3> hi) {
        Aabb b;
        for (int a = 0; a < 3; ++a) {
            b.min[a] = float(origin + (lo[a] + 0.25) * size);
            b.max[a] = float(origin + (hi[a] + 0.75) * size);
        }
        return b;
    };
    // The cells a box covers, from the cell size as the lattice indexes them.
    auto cells_of = [&](const Aabb& b) {
        std::uint64_t n = 1;
        for (int a = 0; a < 3; ++a)
            n *= std::uint64_t(std::floor((b.max[a] - origin) / size) - std::floor((b.min[a] - origin) / size) + 1);
        return n;
    };
    const Aabb from = box_of({1, 1, 1}, {3, 1, 1}), to = box_of({5, 5, 5}, {6, 6, 5});
    const std::uint64_t k = cells_of(from), k2 = cells_of(to);
    ASSERT_EQ(k, 3u);
    ASSERT_EQ(k2, 4u);
    const Uid uid = 5000;
    EXPECT_EQ(writes_over(*s, [&] { s->insert(Object(uid, from)); }), k);
    EXPECT_EQ(writes_over(*s, [&] { s->move(Object(uid, to)); }), k + k2);
    // The same cells: each of them rewrites the box copy.
    EXPECT_EQ(writes_over(*s, [&] { s->move(Object(uid, shifted(to, Vec3{0.01f, 0.01f, 0.01f}))); }), k2);
    EXPECT_EQ(writes_over(*s, [&] { s->commit(); }), 0u);
    EXPECT_EQ(writes_over(*s, [&] { s->remove(uid); }), k2);
    s->check();
}

TEST(UpdateWrites, GridsPayMoreToMoveALongObjectThanASmallOne) {
    std::vector<Object> objects = lattice_scene();
    const Object small(2001, Aabb{{5.05f, 5.05f, 5.05f}, {5.15f, 5.15f, 5.15f}});
    const Object long_one(2002, Aabb{{1.1f, 5.05f, 5.05f}, {8.9f, 5.15f, 5.15f}});  // about 8 cells along x
    objects.push_back(small);
    objects.push_back(long_one);
    for (const char* name : {"ug", "hg"}) {
        SCOPED_TRACE(name);
        auto s = built(name, objects);
        for (const Vec3& d : {Vec3{0.001f, 0.0f, 0.0f}, Vec3{0.0f, 1.0f, 0.0f}}) {  // same cells; a cell over
            auto move = [&](const Object& o) {
                return writes_over(*s, [&] {
                    s->move(Object(o.uid, shifted(o.box, d)));
                    s->commit();
                });
            };
            const std::uint64_t small_writes = move(small), long_writes = move(long_one);
            EXPECT_GT(small_writes, 0u);
            EXPECT_GE(long_writes, 4 * small_writes);
            s->check();
            s->build(objects);  // back to the start for the next shift
            s->commit();
        }
    }
}

TEST(UpdateWrites, BruteForceAndPeersKeepNone) {
    const std::vector<Object> objects = test::generated_scene("uniform", 200, 1, 5).initial;
    for (const char* name : {"bf", "bullet_dbvt"}) {
        SCOPED_TRACE(name);
        auto s = built(name, objects);
        const Object& o = objects.front();
        s->move(Object(o.uid, shifted(o.box, Vec3{1.0f, 1.0f, 1.0f})));
        s->remove(objects.back().uid);
        s->insert(Object(100000, o.box));
        s->commit();
        EXPECT_EQ(s->writes(), 0u);
    }
}

/// writes() after the build and after each frame's update of `r` (the simulator's order: removes,
/// inserts, moves, commit).
std::vector<std::uint64_t> writes_per_frame(const Recording& r, const std::string& name, const nlohmann::json& params) {
    auto s = built(name, r.initial, params);
    std::vector<std::uint64_t> seq{s->writes()};
    for (const Frame& f : r.frames) {
        for (Uid uid : f.removes) s->remove(uid);
        for (const Object& o : f.inserts) s->insert(o);
        for (const Object& o : f.moves) s->move(o);
        s->commit();
        seq.push_back(s->writes());
    }
    s->check();
    return seq;
}

TEST(UpdateWrites, AReplayCountsTheSameWrites) {
    const Recording r = test::generated_scene("irregular", 400, 6, 21, 0.1);
    std::vector<Case> cases = own_cases();
    // A progressive rebuild started at every commit: its next tree's writes are reported too.
    cases.push_back({"wbvh", {{"rebuild_ratio", 0.5}}});
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name + " " + c.params.dump());
        const std::vector<std::uint64_t> first = writes_per_frame(r, c.name, c.params);
        EXPECT_EQ(writes_per_frame(r, c.name, c.params), first);
        EXPECT_GT(first.front(), 0u);  // the build writes
        for (std::size_t i = 1; i < first.size(); ++i) {
            if (r.frames[i - 1].change_count() > 0) {
                EXPECT_GT(first[i], first[i - 1]) << "frame " << i - 1;
            }
        }
    }
}

TEST(UpdateWrites, WideBvhCountsTheBlocksOfItsProgressiveRebuild) {
    const std::vector<Object> objects = test::generated_scene("uniform", 400, 1, 8).initial;
    // A rebuild at every commit after a change, at the fastest speed; and none.
    auto rebuilding = built("wbvh", objects, {{"rebuild_ratio", 0.5}, {"rebuild_speed", 1000.0}});
    auto keeping = built("wbvh", objects, {{"rebuild_ratio", 0.0}, {"rebuild_after", 0.0}});
    std::uint64_t with_rebuild = 0, without = 0;
    for (int frame = 0; frame < 10 && rebuilding->stats()["rebuilds"].get<int>() == 0; ++frame) {
        const Object& o = objects[std::size_t(frame)];
        const Object moved(o.uid, shifted(o.box, Vec3{0.001f, 0.0f, 0.0f}));
        with_rebuild += writes_over(*rebuilding, [&] {
            rebuilding->move(moved);
            rebuilding->commit();
        });
        without += writes_over(*keeping, [&] {
            keeping->move(moved);
            keeping->commit();
        });
    }
    ASSERT_EQ(rebuilding->stats()["rebuilds"].get<int>(), 1);
    // The new tree's blocks were each written by its build, on top of the moves' lanes and refits.
    EXPECT_GE(with_rebuild, without + rebuilding->stats()["nodes"].get<std::uint64_t>());
    rebuilding->check();
}

}  // namespace
}  // namespace rcb

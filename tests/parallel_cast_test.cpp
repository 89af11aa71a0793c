// Parallel ray batches (`cast_threads`): every own structure gives, with two threads, the hit lists
// of one thread byte for byte (same hits, same order, same ray boundaries), is exact against the
// ground truth, and its closest-hit and any-hit queries are unaffected.
#include <gtest/gtest.h>

#include <string>

#include "core/accel/scan/brute_force.h"
#include "core/accel/bvh/dynamic_bvh.h"
#include "core/accel/grid/hash_grid.h"
#include "core/accel/bvh/linear_bvh.h"
#include "core/accel/grid/uniform_grid.h"
#include "core/accel/bvh/wide_bvh.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

const char* const kOwn[] = {"bf", "ug", "hg", "dbvh", "lbvh", "wbvh"};

TEST(ParallelCast, EveryOwnStructureMatchesGroundTruthWithTwoThreads) {
    // The simulator also compares the timed (parallel) pass with the counting (one-thread) pass
    // byte for byte and throws on any difference.
    for (const char* name : kOwn)
        for (const test::NamedScene& s : test::hard_scenes()) {
            test::expect_matches_ground_truth(s.recording, name, {{"cast_threads", 2}}, s.name);
            test::expect_matches_ground_truth(s.recording, name, {{"cast_threads", 2}, {"query", "candidates"}},
                                              s.name);
        }
}

/// Replays `r` into S with one and with two cast threads and compares every frame's batch, the
/// closest and the any hit of every ray; `candidates` at the candidate level.
template <class S>
void expect_same_as_one_thread(const test::NamedScene& scene, bool candidates, const char* name) {
    typename S::Params one, two;
    two.cast_threads = 2;
    S a(one), b(two);
    ASSERT_EQ(b.cast_threads(), 2);
    a.set_candidates_only(candidates);
    b.set_candidates_only(candidates);
    a.build(scene.recording.initial);
    b.build(scene.recording.initial);
    HitLists ha, hb;
    std::size_t parallel_batches = 0;
    for (std::size_t f = 0; f < scene.recording.frames.size(); ++f) {
        const Frame& frame = scene.recording.frames[f];
        for (S* s : {&a, &b}) {
            for (Uid uid : frame.removes) s->remove(uid);
            for (const Object& o : frame.inserts) s->insert(o);
            for (const Object& o : frame.moves) s->move(o);
            s->commit();
        }
        a.cast(frame.rays, ha);
        b.cast(frame.rays, hb);
        EXPECT_EQ(a.last_cast_chunks(), 1u);
        parallel_batches += b.last_cast_chunks() > 1;
        const std::string where = std::string(name) + " " + scene.name + " frame " + std::to_string(f);
        ASSERT_EQ(ha.offsets, hb.offsets) << where;
        ASSERT_EQ(ha.uids, hb.uids) << where;
        for (const Segment& ray : frame.rays) {
            const auto ca = a.cast_closest(ray), cb = b.cast_closest(ray);
            ASSERT_EQ(ca.has_value(), cb.has_value()) << where;
            if (ca) {
                EXPECT_TRUE(ca->uid == cb->uid && ca->t == cb->t) << where;
            }
            EXPECT_EQ(a.cast_any(ray), b.cast_any(ray)) << where;
        }
        b.validate();
    }
    // Batches of 32 rays or more run in chunks; the hard scenes cast 64 per frame.
    std::size_t big = 0;
    for (const Frame& frame : scene.recording.frames) big += frame.rays.size() >= 32;
    EXPECT_EQ(parallel_batches, big) << name << " " << scene.name;
}

template <class S>
void check_structure(const char* name) {
    std::vector<test::NamedScene> scenes = test::hard_scenes();
    scenes.push_back({"irregular-3000", test::generated_scene("irregular", 3000, 4, 7, 0.2)});
    for (const test::NamedScene& s : scenes)
        for (bool candidates : {false, true}) expect_same_as_one_thread<S>(s, candidates, name);
}

TEST(ParallelCast, HitListsIdenticalToOneThread) {
    check_structure<BruteForce>("bf");
    check_structure<UniformGrid>("ug");
    check_structure<HashGrid>("hg");
    check_structure<DynamicBvh>("dbvh");
    check_structure<LinearBvh>("lbvh");
    check_structure<WideBvh>("wbvh");
}

TEST(ParallelCast, ThesisResetModeOfTheUniformGrid) {
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "ug", {{"thesis_reset", true}, {"cast_threads", 2}}, s.name);
}

}  // namespace
}  // namespace rcb

// Brute force against the double-precision ground truth, and the ground truth against an
// independent check written differently (interval arithmetic per axis, no slabs object).
#include <gtest/gtest.h>

#include "core/truth/ground_truth.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "accel/scan/brute_force.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

TEST(GroundTruth, AgreesWithAnIndependentTestOnRandomAndAxisAlignedCases) {
    Random rng(42);
    int checked = 0;
    for (int i = 0; i < 200000; ++i) {
        // Coordinates on a coarse lattice so that touching and axis-parallel cases are frequent.
        auto q = [&] { return double(int(rng.below(9)) - 4); };
        Aabbd b{{q(), q(), q()}, {q(), q(), q()}};
        for (int a = 0; a < 3; ++a)
            if (b.min[a] > b.max[a]) std::swap(b.min[a], b.max[a]);
        Segmentd s{{q(), q(), q()}, {q(), q(), q()}};
        const Contact c = classify_contact(s, b);
        const bool exact = test::reference_hit(s, b);
        // With integer coordinates the exact answer is exact: a "hit" must be a hit and a "miss" a miss.
        if (c == Contact::hit) {
            EXPECT_TRUE(exact);
        }
        if (c == Contact::miss) {
            EXPECT_FALSE(exact);
        }
        // Touching includes every exact contact that is not robust; exact must never be "miss".
        ++checked;
    }
    EXPECT_EQ(checked, 200000);
}

TEST(GroundTruth, ClassifiesTouchesAsEitherWayAndCrossingsAsHits) {
    const Aabbd unit{{0, 0, 0}, {1, 1, 1}};
    EXPECT_EQ(classify_contact({{-1, 0.5, 0.5}, {2, 0.5, 0.5}}, unit), Contact::hit);     // through the middle
    EXPECT_EQ(classify_contact({{-1, 1, 0.5}, {2, 1, 0.5}}, unit), Contact::touch);       // along the top face
    EXPECT_EQ(classify_contact({{-1, 1.5, 0.5}, {2, 1.5, 0.5}}, unit), Contact::miss);    // clearly above
    EXPECT_EQ(classify_contact({{0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}}, unit), Contact::hit);  // a point inside
    // A flat box crossed squarely must be hit, though it has no interior.
    const Aabbd flat{{0, 0, 0}, {1, 0, 1}};
    EXPECT_EQ(classify_contact({{0.5, -1, 0.5}, {0.5, 1, 0.5}}, flat), Contact::hit);
    EXPECT_EQ(classify_contact({{0.5, 1, 0.5}, {0.5, 2, 0.5}}, flat), Contact::miss);
}

TEST(GroundTruth, VerifyCountsMissedExtraAndDuplicateHits) {
    const std::vector<Object> objects{{1, {{0, 0, 0}, {1, 1, 1}}}, {2, {{5, 5, 5}, {6, 6, 6}}}};
    const GroundTruth truth(objects);
    const std::vector<Segment> rays{{{-1, 0.5f, 0.5f}, {2, 0.5f, 0.5f}}};  // hits 1 only
    HitLists hits;
    hits.uids = {2, 2};  // misses 1, reports 2 (extra) twice (duplicate)
    hits.end_ray();
    const Verification v = truth.verify(rays, hits);
    EXPECT_EQ(v.missed, 1u);
    EXPECT_EQ(v.extra, 1u);
    EXPECT_EQ(v.duplicate, 1u);
}

TEST(BruteForce, MatchesGroundTruthOnEveryHardScene) {
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "bf", {}, s.name);
}

TEST(BruteForce, ClosestAndAnyHitComeFromTheSameLoop) {
    BruteForce bf;
    const std::vector<Object> objects{
        {1, {{4, -1, -1}, {5, 1, 1}}}, {2, {{2, -1, -1}, {3, 1, 1}}}, {3, {{7, 5, 5}, {8, 6, 6}}}};
    bf.build(objects);
    const Segment s{{0, 0, 0}, {10, 0, 0}};
    const auto closest = bf.cast_closest(s);
    ASSERT_TRUE(closest.has_value());
    EXPECT_EQ(closest->uid, 2u);
    EXPECT_FLOAT_EQ(closest->t, 0.2f);
    EXPECT_TRUE(bf.cast_any(s));
    EXPECT_FALSE(bf.cast_any({{0, 10, 0}, {10, 10, 0}}));
    EXPECT_FALSE(bf.cast_closest({{0, 10, 0}, {10, 10, 0}}).has_value());
}

TEST(BruteForce, CountsEveryBoxTestAndHit) {
    BruteForce bf;
    std::vector<Object> objects;
    for (Uid i = 0; i < 2500; ++i) objects.push_back({i, {{float(i), 0, 0}, {float(i) + 0.5f, 1, 1}}});
    bf.build(objects);
    const std::vector<Segment> rays{{{-1, 0.5f, 0.5f}, {10.25f, 0.5f, 0.5f}}, {{0, 5, 0}, {1, 5, 0}}};
    HitLists hits;
    Counters c;
    bf.cast_counted(rays, hits, c);
    EXPECT_EQ(c.n_rb, 5000u);
    EXPECT_EQ(c.n_tp, 11u);  // boxes 0..10
    EXPECT_EQ(c.n_t, 0u);
    EXPECT_EQ(hits.of(0).size(), 11u);
    EXPECT_EQ(hits.of(1).size(), 0u);
}

TEST(BruteForce, ValidateCatchesABrokenIndex) {
    BruteForce bf;
    bf.build(std::vector<Object>{{1, {{0, 0, 0}, {1, 1, 1}}}, {2, {{2, 2, 2}, {3, 3, 3}}}});
    bf.remove(1);
    bf.insert({1, {{0, 0, 0}, {1, 1, 1}}});
    EXPECT_NO_THROW(bf.check());
    EXPECT_EQ(bf.size(), 2u);
}

}  // namespace
}  // namespace rcb

// The segment–box test: touching counts, axis-parallel segments are exact, zero-length segments
// hit the boxes containing their point, and the float test is exact wherever its arithmetic is.
#include <gtest/gtest.h>

#include "core/base/geometry.h"
#include "core/base/random.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

const Aabb unit{{0, 0, 0}, {1, 1, 1}};

TEST(Geometry, TouchingAFaceAnEdgeOrACornerCounts) {
    EXPECT_TRUE(segment_hits_box<float>({{-1, 1, 0.5f}, {2, 1, 0.5f}}, unit));  // along the top face
    EXPECT_TRUE(segment_hits_box<float>({{-1, 1, 1}, {2, 1, 1}}, unit));        // along an edge
    EXPECT_TRUE(segment_hits_box<float>({{2, 0, 0}, {1, 1, 1}}, unit));         // ends on a corner
    EXPECT_TRUE(segment_hits_box<float>({{1, 1, 1}, {2, 2, 2}}, unit));         // starts on a corner
    EXPECT_TRUE(segment_hits_box<float>({{-1, -1, -1}, {0, 0, 0}}, unit));      // ends on the min corner
    EXPECT_FALSE(segment_hits_box<float>({{-1, 1.001f, 0.5f}, {2, 1.001f, 0.5f}}, unit));
    EXPECT_FALSE(segment_hits_box<float>({{2, 2, 2}, {3, 3, 3}}, unit));  // the line would, the segment not
}

TEST(Geometry, AxisParallelSegmentsOnFacePlanesAreExact) {
    // Start exactly on a face plane while parallel to it: 0·∞ must not poison the result.
    for (float y : {0.0f, 1.0f}) {
        EXPECT_TRUE(segment_hits_box<float>({{-1, y, 0.5f}, {2, y, 0.5f}}, unit)) << y;
        EXPECT_TRUE(segment_hits_box<float>({{2, y, 0.5f}, {-1, y, 0.5f}}, unit)) << y;  // reversed
    }
    EXPECT_TRUE(segment_hits_box<float>({{0, 0, -5}, {0, 0, 5}}, unit));  // along an edge line, through
    EXPECT_FALSE(segment_hits_box<float>({{0, 0, 2}, {0, 0, 5}}, unit));  // along the edge line, past it
    // -0.0 direction components (from -0 minus +0) behave like +0.
    EXPECT_TRUE(segment_hits_box<float>({{0.0f, 0.5f, 0.5f}, {-0.0f, 0.5f, 0.5f}}, unit));
    EXPECT_TRUE(segment_hits_box<float>({{-0.0f, -1, 0.5f}, {0.0f, 2, 0.5f}}, unit));
}

TEST(Geometry, ZeroLengthSegmentsHitTheBoxesContainingTheirPoint) {
    EXPECT_TRUE(segment_hits_box<float>({{0.5f, 0.5f, 0.5f}, {0.5f, 0.5f, 0.5f}}, unit));
    EXPECT_TRUE(segment_hits_box<float>({{1, 1, 1}, {1, 1, 1}}, unit));
    EXPECT_TRUE(segment_hits_box<float>({{0, 0.5f, 1}, {0, 0.5f, 1}}, unit));
    EXPECT_FALSE(segment_hits_box<float>({{1.5f, 0.5f, 0.5f}, {1.5f, 0.5f, 0.5f}}, unit));
    const Aabb point{{2, 2, 2}, {2, 2, 2}};
    EXPECT_TRUE(segment_hits_box<float>({{2, 2, 2}, {2, 2, 2}}, point));
    EXPECT_TRUE(segment_hits_box<float>({{2, 2, 0}, {2, 2, 4}}, point));
}

TEST(Geometry, ClipReportsTheEntryAndExitParameters) {
    float tn, tf;
    ASSERT_TRUE(SegmentSlabs({{-1, 0.5f, 0.5f}, {3, 0.5f, 0.5f}}).clip(unit, tn, tf));
    EXPECT_FLOAT_EQ(tn, 0.25f);
    EXPECT_FLOAT_EQ(tf, 0.5f);
    ASSERT_TRUE(SegmentSlabs({{0.5f, 0.5f, 0.5f}, {0.5f, 0.5f, 3}}).clip(unit, tn, tf));  // starts inside
    EXPECT_EQ(tn, 0.0f);
}

TEST(Geometry, FloatTestIsExactWhenItsArithmeticIs) {
    // Lattice points and power-of-two (or zero) directions: every t is exact in float, so the
    // float test must agree with the exact one on every touching and axis-parallel case.
    Random rng(3);
    const float steps[] = {0, 1, -1, 2, -2, 4, -4, 8, -8};
    int touching = 0;
    for (int i = 0; i < 100000; ++i) {
        auto q = [&] { return float(int(rng.below(9)) - 4); };
        Aabb b{{q(), q(), q()}, {q(), q(), q()}};
        for (int a = 0; a < 3; ++a)
            if (b.min[a] > b.max[a]) std::swap(b.min[a], b.max[a]);
        const Vec3 p0{q(), q(), q()};
        const Vec3 d{steps[rng.below(9)], steps[rng.below(9)], steps[rng.below(9)]};
        const Segment s{p0, p0 + d};
        const bool want = test::reference_hit({p0.as<double>(), (p0 + d).as<double>()}, b.as<double>());
        ASSERT_EQ(segment_hits_box(s, b), want)
            << "segment (" << p0.x << "," << p0.y << "," << p0.z << ")+(" << d.x << "," << d.y << "," << d.z
            << ") box min (" << b.min.x << "," << b.min.y << "," << b.min.z << ") max (" << b.max.x << "," << b.max.y
            << "," << b.max.z << ")";
        touching += want;
    }
    EXPECT_GT(touching, 1000);  // the sample really exercised hits
}

}  // namespace
}  // namespace rcb

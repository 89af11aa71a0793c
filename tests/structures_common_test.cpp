// What several structures share (accel/common/, accel/grid/grid.h, accel/bvh/bvh_traversal.h): the loop
// over a range of cells, the outlier trim, the slot tables in both layouts, the peers' exact collector, and
// check()'s one way to fail.
#include <gtest/gtest.h>

#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "accel/interface/structure.h"
#include "accel/grid/grid.h"
#include "accel/common/exact_collector.h"
#include "accel/common/outlier_trim.h"
#include "accel/common/slot_boxes.h"

namespace rcb {
namespace {

Aabb box_at(float x, float half = 0.5f) { return {{x - half, -half, -half}, {x + half, half, half}}; }

TEST(ForEachCell, VisitsEveryCellOfTheRangeOnceXFastest) {
    const grid::CellRange r{{1, -2, 3}, {3, -1, 3}};
    std::vector<grid::Index> seen;
    grid::for_each_cell(r, [&](const grid::Index& i) { seen.push_back(i); });
    ASSERT_EQ(seen.size(), grid::cell_count(r));
    EXPECT_EQ(seen.size(), 6u);
    EXPECT_EQ(seen.front(), (grid::Index{1, -2, 3}));
    EXPECT_EQ(seen[1], (grid::Index{2, -2, 3}));  // x first: the order of a grid's cell array
    EXPECT_EQ(seen.back(), (grid::Index{3, -1, 3}));
}

TEST(ForEachCell, CoversTheWholeLattice) {
    grid::Lattice lat;
    lat.res = {4, 2, 3};
    std::size_t n = 0;
    grid::for_each_cell(lat.cells(), [&](const grid::Index&) { ++n; });
    EXPECT_EQ(n, 24u);
}

TEST(OutlierTrim, OneFarObjectShrinksTheBoundsOnItsAxisOnly) {
    std::vector<float> x(1000);
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = float(i % 100);
    x[17] = 1e6f;  // one object far away on x
    Aabb bounds{{0, 0, 0}, {1e6f, 99, 99}};
    auto low = [&](std::size_t i, int a) { return a == 0 ? x[i] : float(i % 100); };
    const bool trimmed = trim_outliers(bounds, x.size(), low, low);
    EXPECT_TRUE(trimmed);
    EXPECT_LT(bounds.max.x, 100.0f);  // the outlier no longer stretches x
    EXPECT_EQ(bounds.max.y, 99.0f);   // y and z were never stretched
}

TEST(OutlierTrim, FewerThan200SamplesOrAnEvenSpreadAreLeftAlone) {
    Aabb bounds{{0, 0, 0}, {1e6f, 1, 1}};
    auto far = [](std::size_t i, int) { return i == 0 ? 1e6f : 0.0f; };
    EXPECT_FALSE(trim_outliers(bounds, 199, far, far));
    EXPECT_EQ(bounds.max.x, 1e6f);
    Aabb even{{0, 0, 0}, {999, 999, 999}};
    auto spread = [](std::size_t i, int) { return float(i); };
    EXPECT_FALSE(trim_outliers(even, 1000, spread, spread));
    EXPECT_EQ(even.max.x, 999.0f);
}

template <class Table>
void check_swap_remove() {
    Table t;
    for (Uid u = 1; u <= 4; ++u) t.insert(Object{u, box_at(float(u))});
    const std::uint32_t hole = t.remove(2);  // the last slot (uid 4) moves into the hole
    EXPECT_EQ(hole, 1u);
    ASSERT_EQ(t.size(), 3u);
    EXPECT_EQ(t.uid(1), 4u);
    EXPECT_EQ(t.box(1), box_at(4));
    EXPECT_EQ(*t.find(4), 1u);
    EXPECT_EQ(t.find(2), nullptr);
    t.move(Object{4, box_at(9)});
    EXPECT_EQ(t.box(1), box_at(9));
    EXPECT_NO_THROW(t.check("t"));
}

TEST(SlotTables, BothLayoutsKeepTheSlotsDenseOnRemove) {
    check_swap_remove<SlotBoxes>();
    check_swap_remove<SoaSlotBoxes>();
}

TEST(SlotTables, SoaLayoutStoresMinimaAndMaximaPerAxis) {
    SoaSlotBoxes t;
    t.insert(Object{7, {{1, 2, 3}, {4, 5, 6}}});
    EXPECT_EQ(t.layout().min(1)[0], 2.0f);
    EXPECT_EQ(t.layout().max(2)[0], 6.0f);
}

TEST(SlotTables, ValidateNamesTheStructureAndTheBrokenInvariant) {
    SoaSlotBoxes t;
    t.insert(Object{7, {{1, 0, 0}, {0, 1, 1}}});  // min > max on x
    try {
        t.check("bf");
        FAIL() << "check accepted a box with min > max";
    } catch (const std::logic_error& e) {
        EXPECT_EQ(std::string(e.what()), "bf: uid 7 has min > max");
    }
}

/// Three unit boxes on the x axis at x = 0, 2, 4 (uids 10, 11, 12) and one off it (uid 13).
SlotBoxes collector_boxes() {
    SlotBoxes t;
    for (Uid u = 0; u < 3; ++u) t.insert({10 + u, box_at(2.0f * float(u))});
    t.insert({13, {{0, 5, 5}, {1, 6, 6}}});
    return t;
}

TEST(ExactCollector, TestsTheUnpaddedBoxCountsAndRemembersAStop) {
    const SlotBoxes boxes = collector_boxes();
    const SegmentSlabs slabs(Segment{{-1, 0, 0}, {9, 0, 0}});
    std::vector<std::pair<Uid, float>> seen;
    auto all = [&](Uid u, float t) {
        seen.emplace_back(u, t);
        return true;
    };
    ExactCollector c(slabs, boxes, all, false);
    EXPECT_FALSE(c.has_limit());
    EXPECT_EQ(c.offer(3), ExactCollector::Offer::miss);  // uid 13: a candidate the segment misses
    EXPECT_EQ(c.offer(1), ExactCollector::Offer::hit);
    EXPECT_EQ(c.offer(0), ExactCollector::Offer::hit);
    EXPECT_EQ(c.tests(), 3u);
    EXPECT_EQ(c.hits(), 2u);
    ASSERT_EQ(seen.size(), 2u);
    EXPECT_EQ(seen[0].first, 11u);
    EXPECT_FLOAT_EQ(seen[0].second, 0.25f);  // entry at x = 1.5
    EXPECT_FALSE(c.stopped());

    AnyHit any;
    ExactCollector first(slabs, boxes, any, false);
    EXPECT_EQ(first.offer(3), ExactCollector::Offer::miss);
    EXPECT_EQ(first.offer(2), ExactCollector::Offer::stop);
    EXPECT_EQ(first.offer(0), ExactCollector::Offer::stop);  // declined untested
    EXPECT_TRUE(first.stopped());
    EXPECT_EQ(first.tests(), 2u);
    EXPECT_EQ(first.hits(), 1u);
    EXPECT_EQ(any.uid, 12u);

    ClosestHit closest;
    ExactCollector near(slabs, boxes, closest, false);
    ASSERT_TRUE(near.has_limit());
    near.offer(2);
    EXPECT_FLOAT_EQ(near.limit(), 0.45f);  // box 12 entered at x = 3.5
    near.offer(0);
    EXPECT_FLOAT_EQ(near.limit(), 0.05f);
    EXPECT_EQ(closest.uid, 10u);
}

TEST(ExactCollector, AtTheCandidateLevelYieldsEveryOfferUntested) {
    const SlotBoxes boxes = collector_boxes();
    const SegmentSlabs slabs(Segment{{-1, 0, 0}, {9, 0, 0}});
    std::vector<Uid> seen;
    auto all = [&](Uid u, float t) {
        EXPECT_EQ(t, 0.0f);
        seen.push_back(u);
        return true;
    };
    ExactCollector c(slabs, boxes, all, true);
    EXPECT_EQ(c.offer(3), ExactCollector::Offer::hit);
    c.add_tests(4);  // a library's own box tests
    EXPECT_EQ(c.tests(), 4u);
    EXPECT_EQ(c.hits(), 1u);
    EXPECT_EQ(seen, (std::vector<Uid>{13}));
}

TEST(ExactCollector, WithinReachRefusesNonFiniteAndFarSegments) {
    EXPECT_TRUE(within_reach(Segment{{-16, 0, 0}, {16, 0, 0}}, 16));
    EXPECT_FALSE(within_reach(Segment{{-16.5f, 0, 0}, {0, 0, 0}}, 16));
    EXPECT_FALSE(within_reach(Segment{{0, 0, 0}, {0, 0, -17}}, 16));
    EXPECT_FALSE(within_reach(Segment{{0, std::numeric_limits<float>::quiet_NaN(), 0}, {0, 0, 0}}, 16));
    EXPECT_FALSE(within_reach(Segment{{0, 0, 0}, {std::numeric_limits<float>::infinity(), 0, 0}}, 16));
}

/// What a library does is up to it; the frame around it counts the collector's work, or scans when
/// the library refuses the segment, and does nothing without objects.
TEST(ExactCollector, TraverseOrScanCountsTheLibrarysOffersOrScans) {
    const SlotBoxes boxes = collector_boxes();
    const Segment seg{{-1, 0, 0}, {9, 0, 0}};
    Counters sums;
    Counting count{&sums};
    std::vector<Uid> seen;
    auto all = [&](Uid u, float) {
        seen.push_back(u);
        return true;
    };
    traverse_or_scan(seg, boxes, count, all, [](ExactCollector& c) {
        c.offer(0);
        c.offer(3);
        return true;
    });
    EXPECT_EQ(sums.n_rb, 2u);
    EXPECT_EQ(sums.n_tp, 1u);
    EXPECT_EQ(seen, (std::vector<Uid>{10}));
    sums = {};
    seen.clear();
    traverse_or_scan(seg, boxes, count, all, [](ExactCollector&) { return false; });
    EXPECT_EQ(sums.n_rb, 4u);  // the scan tests every box
    EXPECT_EQ(seen, (std::vector<Uid>{10, 11, 12}));
    sums = {};
    bool called = false;
    traverse_or_scan(seg, SlotBoxes{}, count, all, [&](ExactCollector&) { return called = true; });
    EXPECT_FALSE(called);
    EXPECT_EQ(sums, Counters{});
}

}  // namespace
}  // namespace rcb

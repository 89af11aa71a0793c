// The binned SAH split the dbvh's rebuild and the wbvh's builder share (binned_sah.h): the sweep
// picks the cheapest border of all binned axes, computed here again straight from the items; the
// partitions agree with goes_left and with each other under any budget; the sides' boxes are the
// parts' unions; coinciding centroids are not binned and split by size; float costs that overflow
// never split where double ones do (why the wbvh computes in double).
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <vector>

#include "accel/bvh/binned_sah.h"
#include "core/base/random.h"

namespace rcb {
namespace {

SahItem item(const Aabb& box, std::uint32_t id) { return {box, box.center(), id}; }

std::vector<SahItem> random_items(std::uint64_t seed, std::uint32_t n) {
    Random rng(seed);
    std::vector<SahItem> items;
    for (std::uint32_t i = 0; i < n; ++i) {
        const Vec3 c{float(rng.uniform(0, 100)), float(rng.uniform(0, 30)), float(rng.uniform(0, 60))};
        const Vec3 h{float(rng.uniform(0.1, 4)), float(rng.uniform(0.1, 4)), float(rng.uniform(0.1, 4))};
        items.push_back(item(Aabb{c - h, c + h}, i));
    }
    return items;
}

/// The SAH cost of every border, from the items themselves: the cheapest, first axis and lowest
/// border on ties.
template <class Real>
SahSplit cheapest_border(const BinnedSah<Real>& sah, const std::vector<SahItem>& items, Real& best_cost) {
    SahSplit best;
    best_cost = std::numeric_limits<Real>::max();
    for (int a = 0; a < 3; ++a) {
        if (!sah.binned(a)) continue;
        for (int border = 1; border < sah.bins(); ++border) {
            Aabb left = Aabb::empty(), right = Aabb::empty();
            std::uint32_t nl = 0;
            for (const SahItem& it : items) {
                if (sah.bin_of(it.centroid, a) < border)
                    left = merge(left, it.box), ++nl;
                else
                    right = merge(right, it.box);
            }
            const auto nr = std::uint32_t(items.size()) - nl;
            if (nl == 0 || nr == 0) continue;
            const Real cost = sah_area<Real>(left) * Real(nl) + sah_area<Real>(right) * Real(nr);
            if (cost < best_cost) best_cost = cost, best = SahSplit{a, border, nl};
        }
    }
    return best;
}

template <class Real>
void expect_cheapest(std::uint64_t seed, int bins) {
    std::vector<SahItem> items = random_items(seed, 300);
    const Aabb cbounds = grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size());
    BinnedSah<Real> sah;
    ASSERT_TRUE(sah.begin(cbounds, bins));
    sah.add(items.data(), items.data() + items.size());
    const SahSplit got = sah.choose(std::uint32_t(items.size()));
    Real cost;
    const SahSplit want = cheapest_border(sah, items, cost);
    ASSERT_TRUE(want.found());
    EXPECT_EQ(got.axis, want.axis) << "seed " << seed << ", " << bins << " bins";
    EXPECT_EQ(got.bin, want.bin) << "seed " << seed << ", " << bins << " bins";
    EXPECT_EQ(got.left, want.left);
    // The sides' boxes are the unions of the items on each side.
    Aabb left = Aabb::empty(), right = Aabb::empty();
    for (const SahItem& it : items)
        (sah.goes_left(it, got) ? left : right) = merge(sah.goes_left(it, got) ? left : right, it.box);
    const auto [l, r] = sah.sides(got);
    EXPECT_EQ(l, left);
    EXPECT_EQ(r, right);
}

TEST(BinnedSah, ChoosesTheCheapestBorderInFloatAndDouble) {
    for (std::uint64_t seed = 1; seed <= 4; ++seed)
        for (int bins : {2, 5, 16, 256}) {
            expect_cheapest<float>(seed, bins);
            expect_cheapest<double>(seed, bins);
        }
}

TEST(BinnedSah, SplitsTwoClustersBetweenThem) {
    std::vector<SahItem> items;
    for (std::uint32_t i = 0; i < 40; ++i) {
        const float x = i < 15 ? float(i % 5) : 1000.0f + float(i % 7);  // 15 left, 25 right on x
        items.push_back(item(Aabb{{x, 0, float(i)}, {x + 1, 1, float(i) + 1}}, i));
    }
    BinnedSah<float> sah;
    ASSERT_TRUE(sah.begin(grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size()), 16));
    sah.add(items.data(), items.data() + items.size());
    const SahSplit split = sah.choose(40);
    ASSERT_TRUE(split.found());
    EXPECT_EQ(split.axis, 0);
    EXPECT_EQ(split.left, 15u);
    SahItem* mid = sah_partition(sah, split, items.data(), items.data() + items.size());
    ASSERT_EQ(mid - items.data(), 15);
    for (const SahItem* it = items.data(); it != mid; ++it) EXPECT_LT(it->box.max.x, 100.0f);
}

TEST(BinnedSah, PartitionInStepsAgreesWithTheWholePartition) {
    const std::vector<SahItem> items = random_items(7, 500);
    BinnedSah<double> sah;
    ASSERT_TRUE(sah.begin(grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size()), 16));
    sah.add(items.data(), items.data() + items.size());
    const SahSplit split = sah.choose(500);
    ASSERT_TRUE(split.found());
    std::vector<SahItem> whole;
    for (std::uint64_t budget :
         {std::uint64_t(1), std::uint64_t(3), std::uint64_t(64), std::numeric_limits<std::uint64_t>::max()}) {
        std::vector<SahItem> stepped = items;
        SahPartition p;
        p.begin(0, split);
        std::uint64_t steps = 0;
        while (!p.done()) {
            ASSERT_GT(p.step(sah, split, stepped.data(), budget), 0u);
            ASSERT_LT(++steps, 10000u);
        }
        for (std::uint32_t i = 0; i < 500; ++i)
            ASSERT_EQ(sah.goes_left(stepped[i], split), i < split.left) << "budget " << budget << ", item " << i;
        // The same order whatever the budget: a progressive rebuild builds the same tree.
        if (whole.empty())
            whole = stepped;
        else
            for (std::uint32_t i = 0; i < 500; ++i) ASSERT_EQ(stepped[i].id, whole[i].id) << "budget " << budget;
    }
}

TEST(BinnedSah, CoincidingCentroidsAreNotBinnedAndSplitBySize) {
    std::vector<SahItem> items;
    for (std::uint32_t i = 0; i < 9; ++i) {
        const float h = float(1 + (i * 5) % 9);  // sizes 1..9, out of order
        items.push_back(item(Aabb{{-h, -h, -h}, {h, h, h}}, i));
    }
    items.push_back(item(Aabb{{-3, -3, -3}, {3, 3, 3}}, 100));  // ties size 3 (id 5), by id
    BinnedSah<double> sah;
    EXPECT_FALSE(sah.begin(grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size()), 16));
    for (int a = 0; a < 3; ++a) EXPECT_FALSE(sah.binned(a));
    EXPECT_EQ(split_by_size<double>(items.data(), 10), 5u);
    std::vector<float> small;
    for (std::uint32_t i = 0; i < 5; ++i) small.push_back(items[i].box.max.x);
    std::sort(small.begin(), small.end());
    EXPECT_EQ(small, (std::vector<float>{1, 2, 3, 3, 4}));
    for (std::uint32_t i = 5; i < 10; ++i) EXPECT_GE(items[i].box.max.x, 5.0f);
}

TEST(BinnedSah, MedianSplitTakesTheWidestCentroidAxis) {
    std::vector<SahItem> items;
    for (std::uint32_t i = 0; i < 8; ++i) {
        const Vec3 c{float(i % 2), float(7 - i) * 10.0f, 0.0f};  // y spreads widest
        items.push_back(item(Aabb{c, c}, i));
    }
    const Aabb cbounds = grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size());
    EXPECT_EQ(split_at_median(items.data(), 8, cbounds), 4u);
    for (std::uint32_t i = 0; i < 4; ++i) EXPECT_LT(items[i].centroid.y, 35.0f);
}

TEST(BinnedSah, FloatCostsThatOverflowNeverSplitDoubleOnesDo) {
    // Boxes spanning most of the float range: their float areas overflow to infinity, which no
    // border's cost may be taken at; in double the same boxes split.
    const float big = 1.5e38f;
    std::vector<SahItem> items;
    for (std::uint32_t i = 0; i < 6; ++i) {
        const float x = i < 3 ? -big : big * 0.5f;
        items.push_back({Aabb{{x, -big, -big}, {x + big * 0.5f, big, big}}, Vec3{x * 0.5f, 0, 0}, i});
    }
    const Aabb cbounds = grow_centroid_bounds(Aabb::empty(), items.data(), items.data() + items.size());
    BinnedSah<float> f;
    ASSERT_TRUE(f.begin(cbounds, 16));
    f.add(items.data(), items.data() + items.size());
    EXPECT_FALSE(f.choose(6).found());
    BinnedSah<double> d;
    ASSERT_TRUE(d.begin(cbounds, 16));
    d.add(items.data(), items.data() + items.size());
    const SahSplit split = d.choose(6);
    ASSERT_TRUE(split.found());
    EXPECT_EQ(split.axis, 0);
    EXPECT_EQ(split.left, 3u);
}

}  // namespace
}  // namespace rcb

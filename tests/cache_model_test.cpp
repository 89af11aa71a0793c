// The footprint counter: a simulated private cache that counts the lines of the items a batch
// fetches, and the counting pass that feeds it.
#include <gtest/gtest.h>

#include <vector>

#include "accel/model/cache_model.h"
#include "accel/model/counters.h"
#include "accel/registry.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

TEST(CacheModel, CountsEachItemsLinesOnceWhileItFits) {
    std::vector<char> data(64 * 1024);
    CacheModel cache;
    for (std::size_t at = 0; at < data.size(); at += 128) cache.read(&data[at], 112);  // blocks of two lines
    EXPECT_EQ(cache.misses(), 2 * data.size() / 128);
    for (std::size_t at = 0; at < data.size(); at += 128) cache.read(&data[at], 112);
    EXPECT_EQ(cache.misses(), 2 * data.size() / 128);  // 64 KiB fits: every item is held
    cache.read(&data[1], 24);                          // another item, of one line
    EXPECT_EQ(cache.misses(), 2 * data.size() / 128 + 1);
}

TEST(CacheModel, EvictsTheLeastRecentlyReadWhenFull) {
    constexpr std::size_t kItem = 1024, kHeld = CacheModel::kBytes / kItem;
    std::vector<char> data((kHeld + 1) * kItem);
    CacheModel cache;
    for (std::size_t k = 0; k < kHeld; ++k) cache.read(&data[k * kItem], kItem);
    const std::uint64_t cold = cache.misses();
    EXPECT_EQ(cold, kHeld * kItem / CacheModel::kLineBytes);
    cache.read(&data[0], kItem);  // a hit: item 0 is now the most recent, item 1 the least
    EXPECT_EQ(cache.misses(), cold);
    cache.read(&data[kHeld * kItem], kItem);  // one item too many: item 1 leaves
    cache.read(&data[0], kItem);
    EXPECT_EQ(cache.misses(), cold + 16);
    cache.read(&data[kItem], kItem);
    EXPECT_EQ(cache.misses(), cold + 32);
}

TEST(CacheModel, TheCountingPassCountsTheFootprintOfEveryTraversal) {
    // One scene, two ray sets of the same size: one ray repeated, which reads its cells or nodes
    // once and then finds them cached, and rays in random directions, which each read their own.
    const std::vector<Object> objects = test::generated_scene("irregular", 20000, 1, 9).initial;
    const std::vector<Segment> random_rays = test::rays_from_centre(objects, 1000, 4);
    const std::vector<Segment> one_ray(1000, random_rays.front());
    for (const char* name : {"ug", "hg", "dbvh", "lbvh", "wbvh"}) {
        const StructureInfo& info = find_structure(name);
        auto s = info.make(info.defaults(), name);
        s->build(objects);
        s->commit();
        HitLists hits;
        Counters coherent, incoherent, once;
        s->cast_counted(one_ray, hits, coherent);
        s->cast_counted(std::vector<Segment>(1, random_rays.front()), hits, once);
        s->cast_counted(random_rays, hits, incoherent);
        ASSERT_GT(once.n_miss, 0u) << name;
        EXPECT_EQ(coherent.n_miss, once.n_miss) << name;  // the first ray's footprint, then hits
        EXPECT_GT(incoherent.n_miss, 20 * once.n_miss) << name;
        Counters again;
        s->cast_counted(random_rays, hits, again);
        EXPECT_EQ(again, incoherent) << name;  // each batch starts cold: the same rays count the same
    }
    // Brute force reads its boxes in order, which a prefetcher hides: it reports no footprint.
    const StructureInfo& bf = find_structure("bf");
    auto s = bf.make(bf.defaults(), "bf");
    s->build(objects);
    s->commit();
    HitLists hits;
    Counters counted;
    s->cast_counted(random_rays, hits, counted);
    EXPECT_EQ(counted.n_miss, 0u);
}

}  // namespace
}  // namespace rcb

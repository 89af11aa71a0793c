// The coherence counter: a history predictor that learns repeated traversals and misses novel ones,
// deterministically, and the counting pass that feeds it.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "accel/model/counters.h"
#include "accel/model/outcome_predictor.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

/// Feeds `outcomes` as steps (each outcome is a node-hit count) and returns the misses.
std::uint64_t misses_of(const std::vector<std::uint32_t>& outcomes) {
    OutcomePredictor p;
    std::uint64_t n_th = 0;
    for (std::uint32_t o : outcomes) {
        p.next_step(n_th, 0, 0);
        n_th += o;
    }
    p.end(n_th, 0, 0);
    return p.mispredicted();
}

TEST(OutcomePredictor, LearnsARepeatedPathAndMissesRandomOnes) {
    Random rng(3);
    std::vector<std::uint32_t> path;
    for (int i = 0; i < 60; ++i) path.push_back(std::uint32_t(rng.below(3)));
    std::vector<std::uint32_t> repeated, random;
    for (int r = 0; r < 200; ++r) {
        repeated.insert(repeated.end(), path.begin(), path.end());
        for (int i = 0; i < 60; ++i) random.push_back(std::uint32_t(rng.below(3)));
    }
    const std::uint64_t coherent = misses_of(repeated), incoherent = misses_of(random);
    EXPECT_LT(coherent, 2 * path.size());      // the first pass, then next to nothing
    EXPECT_GT(incoherent, random.size() / 2);  // two in three guesses wrong at random
    EXPECT_EQ(misses_of(random), incoherent);  // deterministic
}

TEST(OutcomePredictor, ABranchBeyondTheCountsIsPartOfTheOutcome) {
    // Steps with the same counts (a grid's empty cells) told apart only by the way out each took:
    // one order repeated is learnt, orders drawn at random are not; without the branches every
    // step looks alike.
    Random rng(5);
    std::vector<std::uint32_t> path;
    for (int i = 0; i < 12; ++i) path.push_back(1 + std::uint32_t(rng.below(6)));
    auto misses = [](auto&& way_out, int steps) {
        OutcomePredictor p;
        for (int i = 0; i < steps; ++i) {
            p.next_step(0, 0, 0);
            if (const std::uint32_t bits = way_out(i)) p.branch(bits);
        }
        p.end(0, 0, 0);
        return p.mispredicted();
    };
    const int steps = 12 * 300;
    const std::uint64_t repeated = misses([&](int i) { return path[std::size_t(i % 12)]; }, steps);
    const std::uint64_t random = misses([&](int) { return 1 + std::uint32_t(rng.below(6)); }, steps);
    const std::uint64_t none = misses([](int) { return 0u; }, steps);
    EXPECT_LT(repeated, 4 * path.size());
    EXPECT_GT(random, std::uint64_t(steps) / 2);
    EXPECT_EQ(none, 0u);
}

TEST(OutcomePredictor, TheCountingPassCountsCoherenceForEveryTraversal) {
    // One scene, two ray sets with the same paths in total: one ray repeated, and rays in random
    // directions. Every structure that counts steps sees the repeated ray as coherent.
    const std::vector<Object> objects = test::generated_scene("irregular", 3000, 1, 9).initial;
    const std::vector<Segment> random_rays = test::rays_from_centre(objects, 400, 4);
    const std::vector<Segment> one_ray(400, random_rays.front());
    for (const char* name : {"ug", "hg", "dbvh", "lbvh", "wbvh", "bullet_dbvt"}) {
        const StructureInfo& info = find_structure(name);
        auto s = info.make(info.defaults(), name);
        s->build(objects);
        s->commit();
        HitLists hits;
        Counters coherent, incoherent;
        s->cast_counted(one_ray, hits, coherent);
        s->cast_counted(random_rays, hits, incoherent);
        ASSERT_GT(coherent.n_t, 0u) << name;
        EXPECT_LT(double(coherent.n_mp) / double(coherent.n_t), 0.05) << name;
        EXPECT_GT(double(incoherent.n_mp) / double(incoherent.n_t), 0.1) << name;
        Counters again;
        s->cast_counted(random_rays, hits, again);
        EXPECT_EQ(again, incoherent) << name;  // the same rays count the same
    }
}

}  // namespace
}  // namespace rcb

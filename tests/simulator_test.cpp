// The simulator: phases, results, and that verification really catches a wrong structure.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>

#include "accel/registry.h"
#include "sim/cache_sweep.h"
#include "sim/simulator.h"
#include "accel/scan/brute_force.h"
#include "tests/forwarding_structure.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

/// Brute force that forgets the last hit of every ray with two or more hits.
class ForgetfulBruteForce : public test::Forwarding<ForgetfulBruteForce, BruteForce> {
public:
    struct Params {
        static constexpr auto fields() { return std::tuple{}; }
    };
    explicit ForgetfulBruteForce(const Params& = {}) {}
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        std::vector<std::pair<Uid, float>> all;
        inner_.traverse(
            s, count, [&](Uid u, float t) { return all.emplace_back(u, t), true; }, scratch_);
        if (all.size() >= 2) all.pop_back();
        for (auto [u, t] : all)
            if (!visit(u, t)) return;
    }

private:
    BruteForceScratch scratch_;
};

TEST(Simulator, ReportsEveryFramePhaseAndCounter) {
    const Recording r = test::generated_scene("irregular", 2000, 6, 5);
    SimulationOptions o;
    o.warmup_frames = 2;
    const SimulationResult res = simulate(r, find_structure("bf"), nlohmann::json::object(), o);
    ASSERT_EQ(res.frames.size(), 6u);
    EXPECT_TRUE(res.frames[1].warmup);
    EXPECT_FALSE(res.frames[2].warmup);
    EXPECT_EQ(res.mismatches(), 0u);
    EXPECT_GT(res.memory_bytes, 2000u * 28);
    for (const FrameResult& f : res.frames) {
        EXPECT_EQ(f.rays, 100u);
        EXPECT_GT(f.raycast_ns, 0u);
        EXPECT_EQ(f.counters.n_tp, f.hits);       // the counting pass sees the same hits
        EXPECT_GE(f.counters.n_rb, 100u * 1900);  // BF tests every live object per ray
    }
    const nlohmann::json j = res.to_json();
    for (const char* key : {"structure", "params", "build_ns", "memory_bytes", "mismatches", "update_ns", "raycast_ns",
                            "hits", "n_t", "n_rb", "n_tp"})
        EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_EQ(j["update_ns"].size(), 6u);
}

TEST(Simulator, AnUntimedReplayCountsTheSameWorkAndTimesNothing) {
    const Recording r = test::generated_scene("irregular", 500, 5, 3);
    const nlohmann::json params = {{"density", 2.0}};
    const std::uint64_t before = timed_phases();
    const SimulationResult untimed = simulate(r, find_structure("ug"), params, untimed_replay(1));
    EXPECT_EQ(timed_phases(), before);  // no build, update or ray batch timed
    EXPECT_EQ(untimed.build_ns, 0u);
    SimulationOptions timed;
    timed.warmup_frames = 1;
    const SimulationResult measured = simulate(r, find_structure("ug"), params, timed);
    // A timed run times the build, and per frame its update and each query kind's ray batch.
    std::uint64_t phases = 1;
    for (const FrameResult& f : measured.frames) phases += 1 + std::max<std::size_t>(1, f.kinds.size());
    EXPECT_EQ(timed_phases() - before, phases);
    ASSERT_EQ(untimed.frames.size(), measured.frames.size());
    for (std::size_t i = 0; i < untimed.frames.size(); ++i) {
        const FrameResult &u = untimed.frames[i], &m = measured.frames[i];
        EXPECT_EQ(u.update_ns, 0u);
        EXPECT_EQ(u.raycast_ns, 0u);
        EXPECT_EQ(u.counters, m.counters);  // the same work counted
        EXPECT_EQ(u.hits, m.hits);
        EXPECT_EQ(u.writes, m.writes);
        EXPECT_EQ(u.memory_bytes, m.memory_bytes);
    }
}

TEST(Simulator, VerificationCatchesAStructureThatDropsHits) {
    const Recording r = test::generated_scene("irregular", 1500, 3, 6);
    StructureInfo broken = describe_structure<ForgetfulBruteForce>("forgetful", "drops hits");
    const SimulationResult res = simulate(r, broken, nlohmann::json::object());
    EXPECT_GT(res.mismatches(), 0u);
    EXPECT_EQ(res.mismatches(), res.frames[0].missed + res.frames[1].missed + res.frames[2].missed);
    ASSERT_FALSE(res.examples.empty());
    EXPECT_EQ(res.examples[0].second.kind, Discrepancy::missed);
}

TEST(Simulator, MedianAndMadOfFrames) {
    const Spread s = spread_of({1, 2, 3, 4, 100});
    EXPECT_EQ(s.median, 3);
    EXPECT_EQ(s.mad, 1);
    EXPECT_EQ(spread_of({2, 4}).median, 3);
}

TEST(Simulator, TheMediansIntervalIsTheOrderStatisticsOfTheBinomialAndNarrowsWithMoreValues) {
    // 18 values (a dense.json cell's measured frames): the 95% interval is x(5) .. x(14) (Conover's
    // table: P(Binomial(18, 1/2) <= 4) = 0.015, P(<= 5) = 0.048).
    std::vector<double> v;
    for (int i = 1; i <= 18; ++i) v.push_back(i);
    const Spread s = spread_of(v);
    EXPECT_EQ(s.ci_low, 5);
    EXPECT_EQ(s.ci_high, 14);
    // Below 6 values no interval reaches 95%: the whole range.
    EXPECT_EQ(spread_of({3, 1, 2, 5, 4}).ci_low, 1);
    EXPECT_EQ(spread_of({3, 1, 2, 5, 4}).ci_high, 5);
    // The same noisy source: the interval of 400 draws is narrower than that of 25.
    Random rng(7);
    std::vector<double> few, many;
    for (int i = 0; i < 400; ++i) (i < 25 ? few : many).push_back(1.0 + 0.1 * rng.normal());
    many.insert(many.end(), few.begin(), few.end());
    const Spread a = spread_of(few), b = spread_of(many);
    EXPECT_LT(b.ci_high - b.ci_low, 0.5 * (a.ci_high - a.ci_low));
    EXPECT_LE(b.ci_low, b.median);
    EXPECT_GE(b.ci_high, b.median);
}

TEST(Simulator, OneThreadedConfigurationsAreTimedOnTheThreadsOwnClockAndKeepTheWallTimes) {
    const Recording r = test::generated_scene("uniform", 300, 3, 1);
    SimulationOptions o;
    const SimulationResult one = simulate(r, find_structure("bf"), {}, o);
    EXPECT_EQ(one.clock, TimingClock::thread);
    for (const FrameResult& f : one.frames) {
        EXPECT_EQ(f.raycast_ns, std::min(f.raycast.cpu_ns, f.raycast.wall_ns));
        EXPECT_EQ(f.update_ns, std::min(f.update.cpu_ns, f.update.wall_ns));
        EXPECT_GT(f.raycast.wall_ns, 0u);
    }
    EXPECT_EQ(one.to_json()["clock"], "thread");
    EXPECT_EQ(one.to_json()["raycast_wall_ns"].size(), one.frames.size());
    // A batch cast on two threads is timed on the wall clock: the caller's CPU time would leave the
    // other thread's work out. (TBB allows two threads here even on a one-core machine.)
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 2);
    const SimulationResult two = simulate(r, find_structure("bf"), {{"cast_threads", 2}}, o);
    EXPECT_EQ(two.clock, TimingClock::wall);
    for (const FrameResult& f : two.frames) EXPECT_EQ(f.raycast_ns, f.raycast.wall_ns);
}

TEST(Simulator, AColdCacheChangesNoAnswerOrCounterAndIsReported) {
    const Recording r = test::generated_scene("uniform", 300, 4, 2);
    SimulationOptions warm, cold;
    cold.cold_cache = std::make_shared<const CacheSweep>(std::uint64_t(1) << 20);
    for (const char* name : {"bf", "ug", "wbvh"}) {
        const SimulationResult a = simulate(r, find_structure(name), {}, warm);
        const SimulationResult b = simulate(r, find_structure(name), {}, cold);
        EXPECT_EQ(a.mismatches() + b.mismatches(), 0u) << name;
        ASSERT_EQ(a.frames.size(), b.frames.size());
        for (std::size_t i = 0; i < a.frames.size(); ++i) {
            EXPECT_EQ(a.frames[i].hits, b.frames[i].hits) << name;
            EXPECT_EQ(a.frames[i].writes, b.frames[i].writes) << name;
            EXPECT_EQ(a.frames[i].counters.n_t, b.frames[i].counters.n_t) << name;
            EXPECT_EQ(a.frames[i].counters.n_rb, b.frames[i].counters.n_rb) << name;
        }
        EXPECT_EQ(a.to_json()["cache"], "warm");
        EXPECT_FALSE(a.to_json().contains("cache_sweep_bytes"));
        EXPECT_EQ(b.to_json()["cache"], "cold");
        EXPECT_EQ(b.to_json()["cache_sweep_bytes"], std::uint64_t(1) << 20);
    }
    // Whole lines only: a sweep reads one word of each.
    EXPECT_EQ(CacheSweep(100).bytes(), 64u);
    EXPECT_EQ(CacheSweep(0).bytes(), 0u);
}

}  // namespace
}  // namespace rcb

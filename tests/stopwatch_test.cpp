// The stopwatch: the thread's CPU time leaves out the time the thread did not run, the wall time
// counts it; work on the thread counts on both.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <thread>

#include "core/base/stopwatch.h"

namespace rcb {
namespace {

TEST(Stopwatch, TimeTheThreadSpendsAsleepIsWallTimeButNotCpuTime) {
    const Stopwatch watch;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    const Elapsed e = watch.elapsed();
    EXPECT_GE(e.wall_ns, 30'000'000u);
    EXPECT_LT(e.cpu_ns, 5'000'000u);  // waking up costs microseconds, not the 30 ms asleep
    EXPECT_EQ(on_clock(e, TimingClock::wall), e.wall_ns);
    EXPECT_EQ(on_clock(e, TimingClock::thread_cpu), e.cpu_ns);
}

TEST(Stopwatch, WorkOnTheThreadCountsOnTheCpuClock) {
    const Stopwatch watch;
    std::uint64_t x = 1;
    // Spin until 20 ms of CPU time have passed on this thread: the CPU clock must advance with work.
    while (watch.elapsed().cpu_ns < 20'000'000u) x = x * 6364136223846793005ULL + 1;
    const Elapsed e = watch.elapsed();
    EXPECT_GE(e.cpu_ns, 20'000'000u);
    EXPECT_GE(e.wall_ns + 1'000'000u,
              e.cpu_ns);  // never more CPU than wall time on one thread (1 ms slack for the two clocks' reads)
    EXPECT_NE(x, 0u);
    EXPECT_STREQ(clock_name(TimingClock::thread_cpu), "thread-cpu");
    EXPECT_STREQ(clock_name(TimingClock::wall), "wall");
}

}  // namespace
}  // namespace rcb

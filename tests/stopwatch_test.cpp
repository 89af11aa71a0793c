// The stopwatch: the thread's CPU time leaves out the time the thread did not run, the wall time
// counts it; work on the thread counts on both; the thread's own clock is the lesser of the two,
// and the CPU clock's system call lies outside the wall span.
#include <gtest/gtest.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <thread>
#include <vector>

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
    EXPECT_EQ(on_clock(e, TimingClock::thread), e.cpu_ns);  // the thread waited: its CPU time
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
    EXPECT_EQ(on_clock(e, TimingClock::thread), std::min(e.wall_ns, e.cpu_ns));
    EXPECT_NE(x, 0u);
    EXPECT_STREQ(clock_name(TimingClock::thread), "thread");
    EXPECT_STREQ(clock_name(TimingClock::wall), "wall");
}

std::uint64_t median(std::vector<std::uint64_t> v) {
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    return v[v.size() / 2];
}

TEST(Stopwatch, TheCpuClocksSystemCallLiesOutsideTheWallSpan) {
    // An empty section on the thread's own clock costs the wall clock's reads alone; one read of
    // the CPU clock is a system call, several times that. Were the CPU clock read inside the wall
    // span (or its span reported), the empty section would cost at least one such call.
    constexpr int kSamples = 2001;
    std::vector<std::uint64_t> empty, call;
    for (int i = 0; i < kSamples; ++i) {
        const Stopwatch watch;
        empty.push_back(watch.ns(TimingClock::thread));
        const auto t0 = std::chrono::steady_clock::now();
        timespec ts{};
        ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
        const auto t1 = std::chrono::steady_clock::now();
        call.push_back(std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()));
    }
    EXPECT_LT(2 * median(empty), median(call))
        << "empty section " << median(empty) << " ns, CPU clock read " << median(call) << " ns";
}

}  // namespace
}  // namespace rcb

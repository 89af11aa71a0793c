#include "core/base/stopwatch.h"

#include <time.h>

#include <chrono>

namespace rcb {
namespace {

std::uint64_t wall_now() {
    return std::uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
            .count());
}

std::uint64_t cpu_now() {
    // The kernel reads the thread's scheduler runtime to the nanosecond (a system call: kept
    // outside the wall span, stopwatch.h).
    timespec ts{};
    ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return std::uint64_t(ts.tv_sec) * 1'000'000'000ULL + std::uint64_t(ts.tv_nsec);
}

}  // namespace

const char* clock_name(TimingClock c) { return c == TimingClock::thread ? "thread" : "wall"; }

Stopwatch::Stopwatch() : cpu_start_(cpu_now()), wall_start_(wall_now()) {}

Elapsed Stopwatch::elapsed() const {
    const std::uint64_t wall = wall_now(), cpu = cpu_now();
    return {wall - wall_start_, cpu - cpu_start_};
}

std::uint64_t Stopwatch::ns(TimingClock clock) const { return on_clock(elapsed(), clock); }

}  // namespace rcb

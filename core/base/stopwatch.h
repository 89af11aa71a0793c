#pragma once
/// Timing of one section of work on the calling thread: its wall time (steady_clock) and the
/// thread's CPU time (CLOCK_THREAD_CPUTIME_ID) over the same span.
///
/// On one thread the section's own cost leaves out the time the thread sat preempted while
/// another process used the core (on a shared machine a 4 ms time slice lands in a 1 ms ray batch
/// now and then, and a median over frames of unequal work can jump between them). The CPU clock
/// leaves that out, but reading it is a system call, whose cost varies with what ran before it and
/// with the host, and part of two such calls lies inside every CPU span: a measurable share of a
/// small update (docs/model.md as of commit f3b2207, "The CPU clock's own cost"). The wall span encloses no system call
/// (the CPU clock is read outside it; the wall clock is read in user space), so each span is at
/// least the work, and the lesser of the two is the section's own time: the wall span when the
/// thread ran throughout, the CPU span when it waited (`TimingClock::thread`). Work spread over
/// several threads needs the wall time: the caller's CPU time would leave the other threads out.

#include <cstdint>

namespace rcb {

struct Elapsed {
    std::uint64_t wall_ns = 0;
    std::uint64_t cpu_ns = 0;  ///< the calling thread's CPU time (user + system), its clock's reads included
};

/// Which clock a measurement reports: `thread` (the lesser of the wall and the CPU span) for
/// work on one thread, else `wall`.
enum class TimingClock { wall, thread };
const char* clock_name(TimingClock c);  ///< "wall", "thread"
inline std::uint64_t on_clock(const Elapsed& e, TimingClock c) {
    return c == TimingClock::thread && e.cpu_ns < e.wall_ns ? e.cpu_ns : e.wall_ns;
}

class Stopwatch {
public:
    Stopwatch();              ///< starts now: the CPU clock, then the wall clock
    Elapsed elapsed() const;  ///< the wall clock, then the CPU clock
    /// The elapsed time on `clock`.
    std::uint64_t ns(TimingClock clock) const;

private:
    // Declared in the order they are read: the CPU clock's system call before the wall span opens.
    std::uint64_t cpu_start_, wall_start_;
};

}  // namespace rcb

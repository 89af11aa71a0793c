#pragma once
/// Timing of one section of work on the calling thread: its wall time (steady_clock) and the
/// thread's CPU time (CLOCK_THREAD_CPUTIME_ID) over the same span.
///
/// On one thread the CPU time is the section's own cost: it leaves out the time the thread sat
/// preempted while another process used the core (on a shared machine a 4 ms time slice lands
/// in a 1 ms ray batch now and then, and a median over frames of unequal work can jump between
/// them). Work spread over several threads needs the wall time: the caller's CPU time would
/// leave the other threads out. wall − cpu is the time the thread waited.

#include <cstdint>

namespace rcb {

struct Elapsed {
    std::uint64_t wall_ns = 0;
    std::uint64_t cpu_ns = 0;  ///< the calling thread's CPU time (user + system)
};

/// Which clock a measurement reports: the thread's CPU time for work on one thread, else wall.
enum class TimingClock { wall, thread_cpu };
const char* clock_name(TimingClock c);  ///< "wall", "thread-cpu"
inline std::uint64_t on_clock(const Elapsed& e, TimingClock c) {
    return c == TimingClock::thread_cpu ? e.cpu_ns : e.wall_ns;
}

class Stopwatch {
public:
    Stopwatch();  ///< starts now
    Elapsed elapsed() const;
    /// The elapsed time on `clock`.
    std::uint64_t ns(TimingClock clock) const;

private:
    std::uint64_t wall_start_, cpu_start_;
};

}  // namespace rcb

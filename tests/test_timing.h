#pragma once
/// Made-up times for the tests of choices among measured configurations (the tuner's search and
/// cost model, advise's ranking and descent): a verdict that follows the clock flips on a loaded
/// machine or under the sanitizers, one that follows the counters does not.

#include <cmath>
#include <cstdint>

#include "sim/simulator.h"
#include "tuner/tuning.h"

namespace rcb::test {

/// Times in place of the clock's (TuneCategory::timing, AdviseOptions::timing), from a run's
/// counters: a build of 100 ns per object, an update of 1 µs plus `ns_per_change` per insert,
/// remove or move, and a ray cast (each kind's batch too) of eq. 5.4 with these coefficients,
/// c_rb·N_RB + c_t·N_T + c_prep per ray, in ns. The same run always takes the same time.
inline SimulationTiming counted_timing(double c_rb, double c_t, double c_prep, double ns_per_change = 200) {
    return [=](SimulationResult& r) {
        const auto ns = [](double v) { return std::uint64_t(std::llround(v)); };
        const auto cast_ns = [&](const Counters& c, std::uint32_t rays) {
            return ns(c_rb * double(c.n_rb) + c_t * double(c.n_t) + c_prep * rays);
        };
        r.build_ns = ns(100.0 * double(r.objects));
        for (FrameResult& f : r.frames) {
            f.update_ns = ns(1000 + ns_per_change * (f.inserts + f.removes + f.moves));
            f.raycast_ns = cast_ns(f.counters, f.rays);
            f.update = {f.update_ns, f.update_ns};
            f.raycast = {f.raycast_ns, f.raycast_ns};
            for (KindResult& k : f.kinds) {
                k.raycast_ns = cast_ns(k.counters, k.rays);
                k.raycast = {k.raycast_ns, k.raycast_ns};
            }
        }
    };
}

}  // namespace rcb::test

// Parallel ray batches (`cast_threads`): replays a recording into one structure with one cast thread
// and one with two, and times every frame's update and ray batch of both, alternating which goes
// first, in one process so that both see the same machine. Prints the medians (with min and max)
// per frame, the per-frame ratio of one to two threads, and checks the hit lists are identical.
// Pin it: `taskset -c 0,1 build/bench/parallel_cast scene.rcbscene wbvh`.
//
//   build/bench/parallel_cast RECORDING STRUCTURE [THREADS] [WARMUP]   (defaults 2 and 2)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "core/base/error.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"

namespace {

using namespace rcb;
using bench::Clock;
using bench::ms_since;

void print(const char* what, const std::vector<double>& t) {
    std::printf("  %-22s median %8.3f ms  (min %.3f, max %.3f)\n", what, median(t),
                *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end()));
}

int run(int argc, char** argv) {
    if (argc < 3 || argc > 5) throw InputError("usage: parallel_cast RECORDING STRUCTURE [THREADS] [WARMUP]");
    const Recording rec = read_recording(argv[1]);
    const StructureInfo& info = find_structure(argv[2]);
    const int threads = argc >= 4 ? int(bench::count_arg(argv[3], "THREADS", 2, 64)) : 2;
    const std::size_t warmup = argc >= 5 ? bench::count_arg(argv[4], "WARMUP", 0, 1000000) : 2;
    std::unique_ptr<Structure> s[2] = {info.make(nlohmann::json::object(), "one"),
                                       info.make({{"cast_threads", threads}}, "many")};
    for (auto& st : s) st->build(rec.initial);
    HitLists hits[2];
    std::vector<double> update[2], cast[2], ratio;
    for (std::size_t f = 0; f < rec.frames.size(); ++f) {
        const Frame& frame = rec.frames[f];
        double u[2], c[2];
        for (int k = 0; k < 2; ++k) {
            const int i = (f % 2) ? 1 - k : k;  // alternate which goes first
            Clock::time_point t0 = Clock::now();
            for (Uid uid : frame.removes) s[i]->remove(uid);
            for (const Object& o : frame.inserts) s[i]->insert(o);
            for (const Object& o : frame.moves) s[i]->move(o);
            s[i]->commit();
            u[i] = ms_since(t0);
            t0 = Clock::now();
            s[i]->cast(frame.rays, hits[i]);
            c[i] = ms_since(t0);
        }
        if (hits[0].uids != hits[1].uids || hits[0].offsets != hits[1].offsets)
            throw std::logic_error("frame " + std::to_string(f) + ": the hit lists differ");
        if (f < warmup) continue;
        for (int i = 0; i < 2; ++i) update[i].push_back(u[i]), cast[i].push_back(c[i]);
        ratio.push_back(c[0] / c[1]);
    }
    if (ratio.empty()) throw InputError("no frame after the warm-up");
    std::printf("%s on %s: %zu objects, %zu frames measured, %zu rays per frame\n", info.name.c_str(), argv[1],
                rec.initial.size(), ratio.size(), rec.frames.back().rays.size());
    print("update", update[0]);
    print("rays, 1 thread", cast[0]);
    print(("rays, " + std::to_string(threads) + " threads").c_str(), cast[1]);
    std::vector<double> frame1, frame2;
    for (std::size_t f = 0; f < ratio.size(); ++f)
        frame1.push_back(update[0][f] + cast[0][f]), frame2.push_back(update[1][f] + cast[1][f]);
    print("frame, 1 thread", frame1);
    print(("frame, " + std::to_string(threads) + " threads").c_str(), frame2);
    std::printf("  ray speed-up (median of per-frame ratios) %.2f; hit lists identical\n", median(ratio));
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("parallel_cast", run, argc, argv); }

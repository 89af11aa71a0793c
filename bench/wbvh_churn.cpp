// The wide BVH's quality under churn: a generated scene (irreg-l's generator by default) goes through
// FRAMES frames of changes (1% of the live objects per frame: 80% moves of up to an object's size,
// 10% inserts, 10% removes; seeded), applied as the simulator does (removes, inserts, moves, one
// commit). Every K frames, and after the last, the maintained tree's SAH cost is compared with a
// fresh build of the same objects with the same parameters. Prints those ratios (worst, last,
// mean), the per-frame update time (the changes plus the commit) as median, p99 and max, in wall
// time and in the thread's CPU time (which leaves out the time another process held the core),
// the memory per object (at the end, the most seen after a commit, a fresh build's) and the final
// stats. Pin it: `taskset -c 0 build/bench/wbvh_churn 14000 10000`; the times are one run's,
// repeat it.
//
//   build/bench/wbvh_churn [OBJECTS] [FRAMES] [key=value …]
//     bench keys: every=K (default 500), preset=NAME (default irreg-l: its generator), seed=S (1),
//                 change_fraction=F (0.01), move_scale=M (1: up to the object's longest edge),
//                 insert_share=I (0.1), remove_share=R (0.1)
//     any other key is a wbvh parameter, e.g. rebuild_ratio=1.2
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "accel/interface/params.h"
#include "accel/bvh/wide_bvh.h"

namespace {

using namespace rcb;
using bench::Clock;
using bench::ms_since;

/// This thread's CPU time in milliseconds: unlike the wall clock, it leaves out the time the thread
/// waited for the core (the machine may be shared).
double cpu_ms() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

int run(int argc, char** argv) {
    std::uint32_t objects = 14000, frames = 10000, every = 500;
    std::uint64_t seed = 1;
    std::string preset = "irreg-l";
    double change_fraction = 0.01, move_scale = 1.0, insert_share = 0.1, remove_share = 0.1;
    nlohmann::json params = nlohmann::json::object();
    int positional = 0;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg.find('=') == std::string::npos) {
            const auto v = bench::count_arg(argv[i], positional == 0 ? "OBJECTS" : "FRAMES", 1, 100000000);
            if (positional == 0)
                objects = std::uint32_t(v);
            else if (positional == 1)
                frames = std::uint32_t(v);
            else
                throw InputError("usage: wbvh_churn [OBJECTS] [FRAMES] [key=value …]");
            ++positional;
            continue;
        }
        const auto [key, value] = parse_key_value(arg);
        if (key == "every")
            every = value.get<std::uint32_t>();
        else if (key == "preset")
            preset = value.get<std::string>();
        else if (key == "seed")
            seed = value.get<std::uint64_t>();
        else if (key == "change_fraction")
            change_fraction = value.get<double>();
        else if (key == "move_scale")
            move_scale = value.get<double>();
        else if (key == "insert_share")
            insert_share = value.get<double>();
        else if (key == "remove_share")
            remove_share = value.get<double>();
        else
            params[key] = value;
    }
    if (every == 0 || frames == 0 || objects == 0) throw InputError("OBJECTS, FRAMES and every: at least 1");
    const WideBvh::Params p = params_from_json<WideBvh::Params>(params, "params", "wbvh");

    SceneSettings s = preset_settings(preset);
    s.objects = objects;
    s.frames = frames;
    s.seed = seed;
    s.rays.per_frame = 0;
    s.dynamics.change_fraction = change_fraction;
    s.dynamics.move_scale = move_scale;
    s.dynamics.insert_share = insert_share;
    s.dynamics.remove_share = remove_share;
    const Recording rec = generate_scene(s);
    std::printf("preset %s, %u objects, %u frames of %.3g%% changes (move_scale %.3g), seed %llu\nparams %s\n",
                preset.c_str(), objects, frames, change_fraction * 100, move_scale, (unsigned long long)seed,
                params_to_json(p).dump().c_str());

    WideBvh tree(p);
    Clock::time_point t0 = Clock::now();
    tree.build(rec.initial);
    const double build_ms = ms_since(t0);
    LiveSet live(rec.initial);

    std::vector<double> update, update_cpu, ratios;
    update.reserve(frames);
    update_cpu.reserve(frames);
    double total_ms = 0, peak_bytes_per_object = 0;
    std::uint32_t worst_frame = 0;
    std::printf("%8s %10s %10s %8s %9s %8s\n", "frame", "sah", "fresh", "ratio", "growth", "rebuilds");
    for (std::uint32_t f = 0; f < frames; ++f) {
        const Frame& frame = rec.frames[f];
        const double c0 = cpu_ms();
        t0 = Clock::now();
        for (Uid uid : frame.removes) tree.remove(uid);
        for (const Object& o : frame.inserts) tree.insert(o);
        for (const Object& o : frame.moves) tree.move(o);
        tree.commit();
        update.push_back(ms_since(t0));
        update_cpu.push_back(cpu_ms() - c0);
        total_ms += update.back();
        live.apply(frame);
        peak_bytes_per_object = std::max(peak_bytes_per_object,
                                         double(tree.memory_bytes()) / double(std::max<std::size_t>(1, tree.size())));
        if ((f + 1) % every == 0 || f + 1 == frames) {
            WideBvh fresh(p);
            fresh.build(live.objects());
            ratios.push_back(tree.sah_cost() / fresh.sah_cost());
            if (ratios.back() >= *std::max_element(ratios.begin(), ratios.end())) worst_frame = f + 1;
            const nlohmann::json st = tree.stats();
            std::printf("%8u %10.2f %10.2f %8.3f %9.3f %8d\n", f + 1, tree.sah_cost(), fresh.sah_cost(), ratios.back(),
                        st["sah_growth"].get<double>(), st["rebuilds"].get<int>());
        }
    }
    tree.check();
    WideBvh fresh(p);
    fresh.build(live.objects());
    const double n = double(std::max<std::size_t>(1, tree.size()));
    double mean = 0;
    for (double r : ratios) mean += r / double(ratios.size());
    std::printf("SAH ratio to a fresh build: worst %.3f (frame %u), last %.3f, mean %.3f over %zu samples\n",
                *std::max_element(ratios.begin(), ratios.end()), worst_frame, ratios.back(), mean, ratios.size());
    std::printf("build %.2f ms; update per frame: median %.4f ms, p99 %.4f ms, max %.3f ms, total %.0f ms\n", build_ms,
                median(update), quantile(update, 0.99), *std::max_element(update.begin(), update.end()), total_ms);
    double total_cpu = 0;
    for (double u : update_cpu) total_cpu += u;
    std::printf("update per frame, thread CPU time: median %.4f ms, p99 %.4f ms, max %.3f ms, total %.0f ms\n",
                median(update_cpu), quantile(update_cpu, 0.99), *std::max_element(update_cpu.begin(), update_cpu.end()),
                total_cpu);
    std::printf("memory per object: %.1f B at the end, %.1f B at most, %.1f B for a fresh build\n",
                double(tree.memory_bytes()) / n, peak_bytes_per_object, double(fresh.memory_bytes()) / n);
    std::printf("stats %s\n", tree.stats().dump().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("wbvh_churn", run, argc, argv); }

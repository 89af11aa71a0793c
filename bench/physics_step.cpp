// Where a physics scene's generation spends its time: the Bullet world `rcbench scene gen --generator
// GENERATOR` builds (PhysicsRun, core/scene/generate/physics.h) stepped FRAMES frames, each frame timed
// in three parts:
//   bullet   PhysicsRun::step(): btDiscreteDynamicsWorld::stepSimulation (4 substeps for
//            Broadmark's generators) and what a Broadmark generator does after a frame (kicks, turning pull)
//   record   PhysicsRun::record(): each body's object from its transform, compared with the live
//            set, and the frame's rays (rcbench's recording, in memory)
//   write    RecordingWriter::frame(): validating, encoding and appending the frame to a file
// With `--bullet-only` the frames are stepped and neither recorded nor written: Bullet alone, with
// no recording work between its steps. Prints per-frame medians and means of wall-clock time and
// of the thread's CPU time (which another process on the core does not inflate), and the last
// frame's awake bodies. Pin it: `taskset -c 0 build/bench/physics_step brownian 100000 60`.
//
//   build/bench/physics_step KIND OBJECTS FRAMES [--rays N] [--seed S] [--bullet-only] [--out FILE]
//                            [--deferred-collide] [--nncg] [--iterations N]
//
// FILE (default: a temporary file, deleted at the end) receives the recording, the same bytes as
// `rcbench scene gen --generator KIND --objects OBJECTS --frames FRAMES --rays N --seed S -o FILE`.
// The last three options change the Bullet world (BulletConfig, physics.h) to Broadmark's Bullet
// engine's settings or another iteration count, to time what they would change; the scene then
// differs from `scene gen`'s.
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <numeric>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "core/base/error.h"
#include "core/base/statistics.h"
#include "core/scene/generate/physics.h"
#include "core/scene/recording_stream.h"

namespace {

using namespace rcb;
using bench::Clock;
using bench::ms_since;

struct Options {
    SceneSettings settings;
    bool bullet_only = false;
    std::string out;
    BulletConfig bullet;
};

Options parse(int argc, char** argv) {
    if (argc < 4)
        throw InputError(
            "usage: physics_step GENERATOR OBJECTS FRAMES [--rays N] [--seed S] [--bullet-only] [--out FILE] "
            "[--deferred-collide] [--nncg] [--iterations N]");
    Options o;
    o.settings.generator = argv[1];
    if (!is_physics_generator(o.settings.generator))
        throw InputError("GENERATOR: '" + o.settings.generator + "' is not a physics generator");
    o.settings.objects = std::uint32_t(bench::count_arg(argv[2], "OBJECTS", 1, 10'000'000));
    o.settings.frames = std::uint32_t(bench::count_arg(argv[3], "FRAMES", 1, 100'000));
    o.settings.rays.per_frame = 100;
    for (int i = 4; i < argc; ++i) {
        const std::string a = argv[i];
        const bool has_value = i + 1 < argc;
        if (a == "--bullet-only") {
            o.bullet_only = true;
        } else if (a == "--deferred-collide") {
            o.bullet.deferred_collide = true;
        } else if (a == "--nncg") {
            o.bullet.nncg_solver = true;
        } else if (a == "--iterations" && has_value) {
            o.bullet.solver_iterations = int(bench::count_arg(argv[++i], "--iterations", 1, 1000));
        } else if (a == "--rays" && has_value) {
            o.settings.rays.per_frame = std::uint32_t(bench::count_arg(argv[++i], "--rays", 0, 1'000'000));
        } else if (a == "--seed" && has_value) {
            o.settings.seed = bench::count_arg(argv[++i], "--seed", 0, UINT64_MAX);
        } else if (a == "--out" && has_value) {
            o.out = argv[++i];
        } else {
            throw InputError("unknown or incomplete argument '" + a + "'");
        }
    }
    return o;
}

/// The calling thread's CPU time in milliseconds.
double cpu_ms() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) * 1e3 + double(t.tv_nsec) / 1e6;
}

/// Wall-clock and CPU milliseconds of one part, per frame.
struct Part {
    std::vector<double> wall, cpu;
    template <class F>
    auto time(F&& f) {
        const auto t = Clock::now();
        const double c = cpu_ms();
        struct Done {
            Part& part;
            Clock::time_point t;
            double c;
            ~Done() {
                part.wall.push_back(ms_since(t));
                part.cpu.push_back(cpu_ms() - c);
            }
        } done{*this, t, c};
        return f();
    }
    double total() const { return std::accumulate(wall.begin(), wall.end(), 0.0); }
    double cpu_total() const { return std::accumulate(cpu.begin(), cpu.end(), 0.0); }
};

void print(const char* what, const Part& p) {
    if (p.wall.empty()) return;
    const double n = double(p.wall.size());
    std::printf(
        "  %-7s wall median %9.2f ms  mean %9.2f ms (min %.2f, max %.2f)   cpu median %9.2f ms  mean %9.2f ms\n", what,
        median(p.wall), p.total() / n, *std::min_element(p.wall.begin(), p.wall.end()),
        *std::max_element(p.wall.begin(), p.wall.end()), median(p.cpu), p.cpu_total() / n);
}

int run(int argc, char** argv) {
    const Options o = parse(argc, argv);
    const std::string out =
        o.out.empty() ? (std::filesystem::temp_directory_path() / "physics_step.rcbscene").string() : o.out;
    const auto t0 = Clock::now();
    PhysicsRun run(o.settings, {}, o.bullet);
    RecordingWriter writer(out);
    if (!o.bullet_only) writer.begin(run.meta(), run.initial());
    const double setup_ms = ms_since(t0);
    Part bullet, record, write;
    for (std::uint32_t f = 1; f <= o.settings.frames; ++f) {
        bullet.time([&] { run.step(); });
        if (o.bullet_only) continue;
        const Frame frame = record.time([&] { return run.record(); });
        write.time([&] { writer.frame(frame); });
    }
    if (!o.bullet_only) writer.finish();
    std::printf("physics_step %s: %u objects, %u frames, %u rays per frame%s; setup %.1f ms; awake at the end %zu\n",
                o.settings.generator.c_str(), o.settings.objects, o.settings.frames, o.settings.rays.per_frame,
                o.bullet_only ? ", Bullet alone" : "", setup_ms, run.awake_bodies());
    std::printf("  bullet  %s broadphase collide, %s solver, %d iterations\n",
                o.bullet.deferred_collide ? "deferred" : "immediate (Bullet's default)",
                o.bullet.nncg_solver ? "NNCG" : "sequential impulse", o.bullet.solver_iterations);
    print("bullet", bullet);
    print("record", record);
    print("write", write);
    const double total = bullet.total() + record.total() + write.total();
    const double cpu = bullet.cpu_total() + record.cpu_total() + write.cpu_total();
    std::printf("  total   wall %.1f s, cpu %.1f s for %u frames (%.1f ms, cpu %.1f ms per frame)\n", total / 1e3,
                cpu / 1e3, o.settings.frames, total / double(o.settings.frames), cpu / double(o.settings.frames));
    if (!o.bullet_only && o.out.empty()) std::filesystem::remove(out);
    if (!o.bullet_only) std::printf("  file    %llu bytes\n", static_cast<unsigned long long>(writer.bytes_written()));
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("physics_step", run, argc, argv); }
